// hsd_scenes --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
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

}  // namespace hsd::usage
