// Joint training of the DOE height map and the reconstruction network
// (Baek et al. 2021): one step is
//   patches (radiance I [B, L, S, S], depth Z [B, 1, S, S])
//   -> PSFs of the DOE height h for the occupied layers -> sensor image J + noise
//   -> network -> (Î, D̂) -> loss(Î, I, D̂, 1/Z) -> Adam step into h and θ.
// Adam with one parameter group per part (network, DOE; the DOE is left out
// when frozen; its β₁ is train.doe_adam_beta1; the cube term's path into it through
// the spectral Wiener base scaled by train.base_doe_gradient_scale, gradient_scale.h), warm-up and cosine decay (schedule.h), the network's gradient
// norm clipped, and a NaN/Inf guard that stops with the step and tensor named.
// Every random choice of step k (patches, lighting, noise) is a function of
// (seed, k), so a run resumed from a checkpoint repeats the uninterrupted run
// exactly (same thread count).
// Data-parallel (train/distributed.h): with a DataParallel group each rank
// trains on its slice of the same global batch, with averaged gradients and
// batch statistics of the global batch; rank 0 alone writes files. Without
// one the trainer works in a world of one process (SingleProcess), through
// the same calls.
#pragma once
#include <cmath>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "common/config.h"
#include "data/dataset.h"
#include "data/illuminant_augment.h"
#include "data/patch_sampler.h"
#include "model/unet.h"
#include "optics/doe.h"
#include "optics/material.h"
#include "optics/psf.h"
#include "optics/sensor.h"
#include "train/distributed.h"
#include "train/loss.h"
#include "train/metrics_log.h"
#include "train/precision.h"
#include "train/step_stats.h"

namespace hsd::train {

// A batch of patches with their rendering margin m (data.render_margin_px):
// S' = S + 2m; the sensor image is rendered on S', the network sees its
// centre S + 2c (c = train.network_context_px <= m) and the loss the centre S×S.
struct Batch {
  torch::Tensor radiance;   // [B, L, S', S']
  torch::Tensor depth_m;    // [B, 1, S', S']
  int64_t first_index = 0;  // index of image 0 within the global batch (keys its noise draws)
};

// data.render_margin_px resolved: the PSF's reach plus 3σ of the soft layer
// masks when negative (the default), then a patch's image is the whole
// scene's image at its pixels (tests: sensor, margin).
int64_t render_margin_px(const Config& cfg);

// The simulator's spec for training: make_psf_spec with the joint depth
// basis on (optics/psf.h), since the kernels are reused at every step.
optics::PsfSpec training_psf_spec(const Config& cfg, const optics::Material& material, torch::Device device);

// InputError naming train.batch_size unless the global batch splits evenly over the ranks.
void check_global_batch(const Config& cfg, int world_size);

class Trainer {
 public:
  // Optics, DOE, network and optimiser from the config (no data yet). With a
  // group, train.batch_size is the global batch and must split evenly over
  // the ranks; parameters are broadcast from rank 0.
  explicit Trainer(const Config& cfg, std::shared_ptr<DataParallel> group = nullptr);

  // Loads (generating it first if allowed) the dataset: train patches, and
  // train.val_patches fixed validation patches from the val split.
  void attach_data();
  // The training batch of step k: a function of (seed, k) only; with a group,
  // this rank's slice of it.
  Batch train_batch(int64_t step) const;
  // One optimisation step with index `step` (0-based; sets the rates, seeds the noise).
  StepStats step(const Batch& batch, int64_t step);
  // Whether step k takes the DOE's gradient and moves it (a trained DOE and
  // k a multiple of train.doe_every); the other steps train the network alone.
  bool doe_learns_at(int64_t step) const { return doe_trained_ && step % cfg_.train.doe_every == 0; }
  // Phase timings of the following steps into *p (nullptr: off, the default).
  void set_profile(StepProfile* p) { profile_ = p; }
  // Loss and metrics on the fixed validation patches (network in eval mode,
  // fixed noise); with a group each rank takes a share and the sums are combined.
  ValStats validate();

  // Checkpoint: a torch pickle dict (network, DOE, Adam state, next step; also
  // height_map_m and doe_pitch_m so it serves as a height-map file). Atomic.
  // With weight averaging (train.ema_decay) the file's model is the average
  // and the optimiser's weights are kept beside it (train/checkpoint.h).
  void save_checkpoint(const std::string& path, int64_t next_step);
  // Returns the next step; InputError naming the file for a mismatch. With a
  // group every rank reads it (same step required), then takes rank 0's values.
  // Afterwards the network and DOE hold the file's model (the average, with
  // weight averaging); training steps continue from its optimiser's weights.
  int64_t load_checkpoint(const std::string& path);
  // train.init_checkpoint: the network's weights (parameters and buffers) from
  // a training checkpoint of a config with the same network; nothing else
  // (DOE, optimizer, step). Call before attach_data, which then leaves the
  // heads as loaded. InputError naming the file for a missing or mismatched entry.
  void start_from(const std::string& path);

  // The whole run with its outputs in out_dir (docs/formats.md: metrics.csv,
  // checkpoints/last.pt, config.json; plus curves.png, val/ pictures). With a
  // group only rank 0 writes; all ranks end together.
  void run(const std::string& out_dir, bool resume);
  // Before any data is loaded: InputError (exit 2) naming the file if
  // out_dir's checkpoint or metrics.csv cannot be resumed from.
  void check_resume(const std::string& out_dir);
  bool writes_outputs() const { return rank_ == 0; }

  torch::Tensor height() const { return doe_.height().detach(); }
  // The imaging PSFs' provider for simulate_sensor: a fixed stack
  // (optics.psf_source: the all-in-focus control's or a file's), or nullptr
  // (the DOE's PSFs from psf()).
  const optics::PsfProvider& fixed_psf() const { return fixed_psf_; }
  // Every band's and depth's imaging PSF [L, Z, P, P] (the DOE's or the fixed
  // stack), no gradient. When the design cannot change between steps (a
  // frozen DOE without fabrication noise, or a fixed PSF source) it is
  // computed once and kept until the DOE's parameter is written (a loaded
  // checkpoint): read-only.
  torch::Tensor psf_stack() const;
  // model.preinverse = "wiener": hands the network the RGB PSFs of the current
  // DOE (no gradient), and with model.residual = "spectral_wiener" its band
  // PSFs; called by validation, pictures, evaluation and after a checkpoint
  // is loaded. Training steps set their own (with the gradient).
  void refresh_preinverse();
  void refresh_preinverse(const torch::Tensor& all);  // from psf_stack() at hand
  // With model.read_illuminant: gives the network the illuminant reader's
  // moments from the training split of data.root when it has none (a
  // checkpoint written before checkpoints stored them). When data.root has
  // no training split of reflectance scenes (a held-out set such as
  // hsd_scenes --real), warns and turns the reader off: the base keeps the
  // equal weights. No-op otherwise, and for a checkpoint that carries them.
  void ensure_illuminant_moments();
  // The constant-depth baseline's inverse depth [1/m]: the training split's
  // median (attach_data, or a checkpoint that stores it); NaN when unknown.
  double baseline_inv_depth() const { return baseline_inv_depth_; }
  // The network's training arithmetic (train.precision resolved).
  const TrainingPrecision& precision() const { return precision_; }
  model::HsdNet& net() { return net_; }
  optics::Doe& doe() { return doe_; }
  const optics::PsfSimulator& psf() const { return *psf_; }
  const optics::SensorModel& sensor() const { return sensor_; }

 private:
  // The reader's moments from these (reflectance) training scenes, or the
  // reader turned off with a warning when one is a radiance.
  void give_illuminant_moments(const std::vector<data::LoadedScene>& train_scenes);
  // The pieces of step(): the learning rates of step k (into the optimizer),
  // the sensor image of the batch (with the pre-inversion's RGB PSFs when the
  // network has one), the global batch's loss terms (total, cube, depth, TV;
  // NumericalError when not finite), and the gradients averaged, checked,
  // clipped and applied.
  struct StepImage {
    optics::SensorImage image;
    torch::Tensor rgb_psf;   // [Z, 3, P, P] of the design, with the gradient; undefined without a pre-inversion
    torch::Tensor band_psf;  // [L, Z, P, P] of the design, with the gradient; undefined without a spectral Wiener base
  };
  StepStats set_learning_rates(int64_t step);
  // kept: render through the current design's kept PSFs (kept_psf_stack)
  // where no fabrication noise perturbs them (a step that leaves the DOE be).
  StepImage render_step(const Batch& batch, int64_t step, optics::PsfProvider provider, bool kept = false);
  // The design's PSF stack [L, Z, P, P] without a graph, computed once per
  // value of the DOE parameter (keyed on its version) and kept.
  torch::Tensor kept_psf_stack() const;
  std::vector<double> global_loss_terms(const LossTerms& L, int64_t step);
  void apply_gradients(int64_t step);
  // The pieces of run(): a validation into metrics (pictures and, if
  // log_line, the log line on rank 0), and the progress bar's suffix.
  void record_validation(MetricsLog& metrics, int64_t step, const std::string& val_dir, bool log_line);
  std::string progress_suffix(double loss, double seconds, int64_t steps, double collective_seconds) const;
  void write_val_pictures(const std::string& dir, int64_t step);
  // The network on its view of a rendered window [B, 3, S', S'] (net_view; the
  // pre-inversion, the spectral Wiener base and the fused reader's costs,
  // when on, of the whole window, then that view), cropped to the centre patch.
  model::NetOutput reconstruct_window(const torch::Tensor& window);
  // The fused reader's costs of a window, cropped to the network's view
  // (net_view); undefined unless model.fuse_defocus_reader and eval mode.
  torch::Tensor fused_reader_cost(const torch::Tensor& window) const;
  std::vector<int64_t> all_layers() const;  // 0 .. Z−1
  std::vector<int64_t> all_bands() const;   // 0 .. L−1
  // The centre patch_size_px × patch_size_px of [B, C, S', S'] (itself when S' = S).
  torch::Tensor centre(const torch::Tensor& t) const;
  // What the network sees of a window [B, C, S', S']: its centre, the patch
  // and train.network_context_px on every side (itself when no larger;
  // undefined stays undefined).
  torch::Tensor net_view(const torch::Tensor& t) const;
  // The network's outputs over its view cropped to the patch (centre).
  model::NetOutput to_patch(model::NetOutput o) const;
  std::vector<torch::Tensor> trained_parameters() const;  // what Adam updates
  std::vector<std::string> trained_names() const;         // theirs in checkpoints: "net.<name>", "doe.raw"
  // Weight averaging (train.ema_decay > 0): the trained parameters and
  // average_ hold the optimiser's weights and their moving average, one in
  // each; hold_in_parameters(true) puts the average in the parameters
  // (validation, pictures, checkpoints, evaluation), false the optimiser's
  // weights (training steps); a no-op when averaging is off. reset_average()
  // starts the average afresh from the parameters (after they are set from
  // outside: heads, init_checkpoint).
  void hold_in_parameters(bool average);
  void reset_average();
  void update_average(int64_t step);
  void swap_average();
  std::vector<torch::Tensor> replicated_state(bool with_buffers = true) const;  // parameters, buffers, Adam moments
  // Every checkpoint: the ranks' parameters must agree (they can only drift by
  // rounding on unlike hosts); a warning and rank 0's values otherwise.
  void check_replicas_agree(int64_t step);
  Config cfg_;
  std::shared_ptr<Collectives> ranks_;  // a DataParallel group, or SingleProcess
  optics::PsfProvider shared_psf_;  // training PSFs shared out over the ranks (distributed.split_psf)
  optics::PsfProvider fixed_psf_;   // optics.psf_source = "all_in_focus": the control's PSFs
  bool doe_trained_ = true;         // false when frozen (train.freeze_doe) or unused (a fixed PSF source)
  // The imaging PSFs are the same at every step (frozen or unused DOE, no
  // fabrication noise): psf_stack() keeps them, keyed on the DOE parameter's
  // version counter (bumped by every in-place write, as a checkpoint load's).
  bool psf_still_ = false;
  mutable torch::Tensor kept_psf_;
  mutable int64_t kept_psf_version_ = -1;
  double baseline_inv_depth_ = std::nan("");
  std::vector<torch::Tensor> average_;  // weight averaging's other copy of trained_parameters() (empty: off or not started)
  bool average_in_use_ = false;         // the parameters hold the average, average_ the optimiser's weights
  torch::Tensor upsampling_w_;  // [L, 3] the paper's fixed spectral map: the baselines' (not the network's, when learned)
  bool network_started_ = false;    // start_from() loaded the network: attach_data keeps its heads
  TrainingPrecision precision_;
  StepProfile* profile_ = nullptr;
  int64_t margin_ = 0;              // data.render_margin_px resolved
  int64_t rank_ = 0, world_ = 1;  // ranks_'s
  torch::Device device_;
  optics::Material material_;
  std::unique_ptr<optics::PsfSimulator> psf_;
  optics::SensorModel sensor_;
  optics::Doe doe_;
  model::HsdNet net_{nullptr};
  std::unique_ptr<torch::optim::Adam> opt_;
  LossWeights weights_;
  // data
  std::vector<data::LoadedScene> train_scenes_, val_scenes_;
  std::unique_ptr<data::PatchSampler> sampler_;
  std::unique_ptr<data::IlluminantBank> bank_;
  Batch val_;
};

}  // namespace hsd::train
