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

using namespace hsd;

namespace {

const char* kUsage =
    "hsd_scenes --config FILE [--set key=VALUE ...] [--real] --out DIR\n"
    "  Generates data.generator.{train,val,test}_scenes synthetic HS-D scenes\n"
    "  (width_px x height_px, depths depth_min_m..depth_max_m) on the config's\n"
    "  bands, in the layouts data.generator.layouts mixes (textured tabletop,\n"
    "  dead leaves, classic tabletop), plus a ColorChecker scene (test split,\n"
    "  never train) when data.generator.colorchecker is true. Deterministic for\n"
    "  the config's seed. Prints and writes the realism statistics (textured\n"
    "  fraction, power-spectrum slope, spectral PCs, RGB-unexplained residual,\n"
    "  inverse-depth histogram) beside the CAVE balloons cube's.\n"
    "  Writes DIR/*.exr, DIR/*_srgb.png, DIR/*_depth.png, DIR/manifest.json,\n"
    "  DIR/realism.json, DIR/realism.md, DIR/generator.json (the settings that made\n"
    "  it), DIR/colorchecker_layout.json, DIR/config.json.\n"
    "  --real: instead, the held-out real-derived test set (data/real_test_set.h):\n"
    "  the CAVE balloons cube on fronto-parallel and slanted planes and the\n"
    "  Middlebury Aloe, all in the test split; evaluate it with\n"
    "  hsd_eval --set data.root=DIR.";

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
