// hsd_eval: metrics and pictures of a trained system on a split
// (train/evaluator.h): DIR/metrics.json (CONTRACT.md keys, per scene and
// mean), DIR/report.md, per-scene comparisons and spectra, the ColorChecker
// spectral plot and the DOE's PSF atlas.
#include <filesystem>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "train/evaluator.h"
#include "train/trainer.h"

using namespace hsd;

namespace {

const char* kUsage =
    "hsd_eval --config FILE --checkpoint CKPT [--split test] [--set key=VALUE ...] --out DIR\n"
    "  Evaluates the DOE and network of a training checkpoint on every scene of a\n"
    "  split of data.root: hyperspectral and luminance PSNR/SSIM, depth RMSE/MAE,\n"
    "  ColorChecker reflectance RMSE. Writes DIR/metrics.json, DIR/report.md and\n"
    "  pictures. (--model reconstructor.pt arrives with hsd_export.)";

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  if (args.has("--model"))
    input_error("--model", "TorchScript reconstructors come with hsd_export (not built yet); use --checkpoint CKPT");
  const std::string ckpt = args.option("--checkpoint", "");
  if (ckpt.empty()) input_error("--checkpoint", "required (a training checkpoint, e.g. DIR/checkpoints/last.pt)");
  if (!std::filesystem::exists(ckpt)) input_error(ckpt, "no such checkpoint (--checkpoint)");
  const std::string split = args.option("--split", "test");
  if (split != "train" && split != "val" && split != "test" && split != "all")
    input_error("--split", "expected train, val, test or all, got \"" + split + "\"");
  setup_threads(cfg.threads);
  train::Trainer trainer(cfg);
  trainer.load_checkpoint(ckpt);
  const train::EvalResult r = train::evaluate(trainer, cfg, split, args.out_dir);
  write_resolved_config(cfg, args.out_dir);
  char buf[256];
  std::snprintf(buf, sizeof buf, "mean over %zu scenes: HS PSNR %.2f dB, SSIM %.4f; depth RMSE %.4f m", r.scenes.size(),
                r.mean.hs_psnr_db, r.mean.hs_ssim, r.mean.depth_rmse_m);
  log::info(buf);
  log::info("wrote " + args.out_dir + "/metrics.json, report.md and pictures");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_eval", kUsage, {"--checkpoint", "--model", "--split"}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
