// hsd_train: joint end-to-end training of the DOE and the reconstruction
// network (train/trainer.h). Writes DIR/metrics.csv, DIR/curves.png,
// DIR/val_psnr.png, DIR/val/ (reconstructions, depth maps, error maps and the
// PSF atlas at each validation), DIR/checkpoints/last.pt and DIR/config.json.
// --resume continues from DIR/checkpoints/last.pt exactly.
#include <chrono>
#include <filesystem>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "train/trainer.h"

using namespace hsd;

namespace {

const char* kUsage =
    "hsd_train --config FILE [--set key=VALUE ...] --out DIR [--resume]\n"
    "  Trains the DOE height map and the U-Net together (train.steps steps of\n"
    "  train.batch_size patches of data.patch_size_px from data.root, generated\n"
    "  first if missing and data.generate_if_missing). train.freeze_doe keeps the\n"
    "  DOE fixed. Writes DIR/metrics.csv, DIR/curves.png, DIR/val_psnr.png,\n"
    "  DIR/val/*.png, DIR/checkpoints/last.pt and DIR/config.json. --resume\n"
    "  continues from DIR/checkpoints/last.pt (same results as an uninterrupted\n"
    "  run with the same thread count).";

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  const bool resume = args.has("--resume");
  if (resume && !std::filesystem::exists(args.out_dir + "/checkpoints/last.pt"))
    input_error(args.out_dir + "/checkpoints/last.pt", "no checkpoint to resume from (--resume)");
  setup_threads(cfg.threads);
  train::Trainer trainer(cfg);
  trainer.attach_data();
  make_dirs(args.out_dir);
  write_resolved_config(cfg, args.out_dir);
  const auto t0 = std::chrono::steady_clock::now();
  trainer.run(args.out_dir, resume);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  log::info("done in " + c10::str(secs) + " s: curves " + args.out_dir + "/curves.png, metrics " + args.out_dir +
            "/metrics.csv, reconstructions and PSF atlases " + args.out_dir + "/val/, checkpoint " + args.out_dir +
            "/checkpoints/last.pt");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_train", kUsage, {}, {"--resume"}, true, true};
  return run_app(spec, argc, argv, run);
}
