// hsd_export: a training checkpoint -> DIR/reconstructor.pt, a TorchScript
// module (model/torchscript_export.h; CONTRACT.md signature) loadable by
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
#include "optics/psf_atlas.h"
#include "train/trainer.h"

using namespace hsd;

namespace {

const char* kUsage =
    "hsd_export --config FILE --checkpoint CKPT [--set key=VALUE ...] --out DIR\n"
    "  Writes DIR/reconstructor.pt (TorchScript: forward(x [B, 3, H, W] linear RGB)\n"
    "  -> (hs [B, L, H, W], depth [B, 1, H, W] metres); attributes wavelengths_m,\n"
    "  depth_range_m, camera, doe_init, config_sha, hsd_version), DIR/doe_height.pt,\n"
    "  DIR/psf_atlas.png and DIR/config.json.";

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  const std::string ckpt = args.option("--checkpoint", "");
  if (ckpt.empty()) input_error("--checkpoint", "required (a training checkpoint, e.g. DIR/checkpoints/last.pt)");
  if (!std::filesystem::exists(ckpt)) input_error(ckpt, "no such checkpoint (--checkpoint)");
  setup_threads(cfg.threads);
  train::Trainer trainer(cfg);
  trainer.load_checkpoint(ckpt);
  trainer.net()->eval();
  std::ostringstream sha;
  sha << std::hex << std::hash<std::string>{}(cfg.resolved.dump());
  model::ExportMetadata meta;
  meta.wavelengths_m = cfg.optics.wavelengths_m();
  meta.strings = {{"camera", cfg.sensor.camera},
                  {"doe_init", cfg.optics.doe.init},
                  {"config_sha", sha.str()},
                  {"hsd_version", HSD_VERSION},
                  {"checkpoint", ckpt}};
  if (std::isfinite(trainer.baseline_inv_depth())) meta.numbers["baseline_inv_depth_per_m"] = trainer.baseline_inv_depth();
  torch::jit::Module m = model::export_torchscript(trainer.net(), meta);
  make_dirs(args.out_dir);
  const std::string path = args.out_dir + "/reconstructor.pt";
  write_atomically(path, [&](const std::string& tmp) { m.save(tmp); });
  const torch::Tensor h = trainer.height();
  optics::save_height_file(args.out_dir + "/doe_height.pt", h, cfg.optics.doe_pitch_m);
  {
    torch::NoGradGuard ng;
    optics::write_psf_atlas(args.out_dir + "/psf_atlas.png", trainer.psf_stack().cpu(),
                            trainer.psf().spec().wavelengths_m, trainer.psf().spec().depths_m);
  }
  write_resolved_config(cfg, args.out_dir);
  log::info("wrote " + path + " (load with torch.jit.load / torch::jit::load), doe_height.pt, psf_atlas.png, config.json");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_export", kUsage, {"--checkpoint"}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
