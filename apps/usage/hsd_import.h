// hsd_import --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_import --config FILE --rgb IMAGE --disparity DISP.png [--name NAME] [--scale S]\n"
    "           [--near-m N --far-m F | --focal-px F --baseline-m B --doffs-px D] --out DIR\n"
    "  Lifts an sRGB photograph to reflectance spectra on the config's bands (the\n"
    "  ColorChecker linear model: plausible, not measured, spectra) and turns a\n"
    "  disparity map (8/16-bit PNG, 0 = unknown -> masked) into depth Z, either\n"
    "  calibrated (Z = f B / (d + doffs), full-size pixels) or mapped linearly in\n"
    "  inverse depth onto [near, far] (defaults: data.generator.depth_min_m and\n"
    "  depth_max_m). Writes DIR/NAME.exr, NAME_srgb.png, NAME_depth.png and adds\n"
    "  NAME.exr to DIR/manifest.json (split test).";

}  // namespace hsd::usage
