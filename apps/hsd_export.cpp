// hsd_export: a training checkpoint -> DIR/reconstructor.pt, a TorchScript
// module (model/torchscript_export.h; docs/formats.md signature) loadable by
// torch::jit::load and Python's torch.jit.load, plus the optics the model
// expects: DIR/doe_height.pt (height-map file), DIR/psf_atlas.png and
// DIR/config.json.
#include <functional>
#include <sstream>

#include <torch/script.h>
#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/build_info.h"
#include "common/error.h"
#include "common/log.h"
#include "model/torchscript_export.h"
#include "optics/doe.h"
#include "train/trainer.h"
#include "viz/psf_atlas.h"
#include "usage/hsd_export.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  const std::string ckpt = args.option("--checkpoint", "");
  if (ckpt.empty()) input_error("--checkpoint", "required (a training checkpoint, e.g. DIR/checkpoints/last.pt)");
  if (!std::filesystem::is_regular_file(ckpt)) input_error(ckpt, "no such checkpoint file (--checkpoint)");
  check_output_paths({args.out_dir + "/reconstructor.pt"});
  setup_threads(cfg.threads);
  train::Trainer trainer(cfg);
  trainer.load_checkpoint(ckpt);
  trainer.ensure_illuminant_moments();  // model.read_illuminant: the reader's moments from the training split
  trainer.net()->eval();
  std::ostringstream sha;
  sha << std::hex << std::hash<std::string>{}(cfg.resolved.dump());
  model::ExportMetadata meta;
  meta.wavelengths_m = cfg.optics.wavelengths_m();
  meta.strings = {{"camera", cfg.sensor.camera},
                  {"doe_init", choice_word(cfg.optics.doe.init, cfg.optics.doe.init_path)},
                  {"config_sha", sha.str()},
                  {"hsd_version", HSD_VERSION},
                  {"checkpoint", ckpt}};
  if (std::isfinite(trainer.baseline_inv_depth())) meta.numbers["baseline_inv_depth_per_m"] = trainer.baseline_inv_depth();
  // Everything is computed and checked before the first file is written: a
  // failure leaves no reconstructor.pt or height map behind.
  torch::jit::Module m = model::export_torchscript(trainer.net(), meta);
  const torch::Tensor h = trainer.height();
  check_finite(h, "the DOE height map of " + ckpt);
  torch::Tensor psfs;
  {
    torch::NoGradGuard ng;
    psfs = trainer.psf_stack().cpu();
    check_finite(psfs, "the PSFs of " + ckpt + "'s DOE");
    const torch::Tensor probe = torch::rand({1, 3, 64, 64}, torch::TensorOptions().dtype(torch::kFloat32)) * 0.5;
    const auto [hs, depth] = model::run_reconstructor(m, probe);
    check_finite(hs, "the exported model's cube for a test image");
    check_finite(depth, "the exported model's depth for a test image");
  }
  const std::string path = args.out_dir + "/reconstructor.pt";
  check_output_paths({path, args.out_dir + "/doe_height.pt", args.out_dir + "/psf_atlas.png", args.out_dir + "/config.json"});
  make_dirs(args.out_dir);
  write_atomically(path, [&](const std::string& tmp) { m.save(tmp); });
  optics::save_height_file(args.out_dir + "/doe_height.pt", h, cfg.optics.doe_pitch_m);
  viz::write_psf_atlas(args.out_dir + "/psf_atlas.png", psfs, trainer.psf().spec().wavelengths_m,
                          trainer.psf().spec().depths_m);
  write_resolved_config(cfg, args.out_dir);
  log::info("wrote " + path + " (load with torch.jit.load / torch::jit::load), doe_height.pt, psf_atlas.png, config.json");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_export", kUsage, {"--checkpoint"}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
