// hsd_scenes: a synthetic HS-D dataset (data/synthetic_dataset.h) in the
// contract's layout: DIR/scene_<split>_<i>.exr (reflectance T.<nm> channels on
// the config's bands, Z, mask), DIR/manifest.json with the splits, previews
// beside each scene (<name>_srgb.png under D65, <name>_depth.png), and the
// ColorChecker scene (test split) with DIR/colorchecker_layout.json.
#include <chrono>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/log.h"
#include "data/real_test_set.h"
#include "data/synthetic_dataset.h"
#include "usage/hsd_scenes.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  make_dirs(args.out_dir);  // an unwritable --out is found before any scene is made
  check_output_paths({args.out_dir + "/manifest.json", args.out_dir + "/config.json"});
  setup_threads(cfg.threads);
  const auto t0 = std::chrono::steady_clock::now();
  const data::Manifest m = args.has("--real") ? data::generate_real_test_set(cfg, args.out_dir)
                                              : data::generate_dataset(cfg, args.out_dir);
  write_resolved_config(cfg, args.out_dir);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  log::info("wrote " + std::to_string(m.scenes.size()) + " scenes and manifest.json to " + args.out_dir + " (" +
            c10::str(secs) + " s)");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_scenes", kUsage, {}, {"--real"}, true, true};
  return run_app(spec, argc, argv, run);
}
