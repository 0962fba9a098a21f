// Training checkpoints (docs/formats.md): a torch pickle dict of the next
// step, the DOE ("doe.raw", plus "height_map_m" and "doe_pitch_m" so the file
// serves as a height-map file), the network ("net.<name>": parameters and
// buffers), Adam's moments per parameter ("adam.<group>.<index>.exp_avg",
// "exp_avg_sq", "step") and the constant-depth baseline's inverse depth
// ("baseline.inv_depth_per_m", when known), and the illuminant reader's
// moments of the training split ("illuminant.mean" [K, L], "illuminant.second"
// [K, L, L], "illuminant.intensity_range" [2]: model/illuminant_reader.h;
// when the network has them), so a model reads the light with the statistics
// it was trained on whatever data it is evaluated on. With weight averaging
// (train.ema_decay) the DOE and network entries are the averaged model, and
// the optimiser's current weights are "live.<name>" (name: "doe.raw" or
// "net.<parameter>"), so a resumed run continues exactly. Reading checks every entry
// (present, shape, finite) before anything is replaced: a damaged or foreign
// file is an InputError naming it and the entry, never a crash or a NaN model.
#pragma once
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <torch/torch.h>

#include "model/unet.h"
#include "optics/doe.h"

namespace hsd::train {

// What a checkpoint restores: references to the trainer's pieces.
struct TrainingState {
  optics::Doe& doe;
  model::HsdNet& net;
  torch::optim::Adam& adam;
  double& baseline_inv_depth;  // 1/m; NaN when unknown
  // Weight averaging: (name, destination) of the optimiser's current weights;
  // read when the file has them (all, or it is an InputError), live_read says so.
  std::vector<std::pair<std::string, torch::Tensor>> live = {};
  bool live_read = false;
  // The illuminant reader's moments, read (all three entries, checked: [K, L]
  // and [K, L, L] with L the network's bands) when the file has them, else
  // left undefined (files written before they were stored have none).
  model::IlluminantMoments illuminant = {};
};

// Extra entries written beside the model: (name, tensor), e.g. "live.net.<parameter>".
using NamedTensors = std::vector<std::pair<std::string, torch::Tensor>>;

// The checkpoint entries of the illuminant reader's moments (names above).
NamedTensors illuminant_entries(const model::IlluminantMoments& m);

// Writes the state and next_step to path, atomically.
void write_checkpoint(const std::string& path, const optics::Doe& doe, const model::HsdNet& net, const torch::optim::Adam& adam,
                      double baseline_inv_depth, int64_t next_step, const NamedTensors& extra = {});
// Replaces the state by the file's (all entries checked first); returns its next step.
int64_t read_checkpoint(const std::string& path, TrainingState& s);
// The network's parameters and buffers alone (train.init_checkpoint): InputError
// naming the file for a missing, mismatched or non-finite entry; nothing replaced then.
void read_network_weights(const std::string& path, model::HsdNet& net);

}  // namespace hsd::train
