// hsd_simulate --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_simulate --config FILE --scene SCENE.exr [--set key=VALUE ...] --out DIR\n"
    "  Renders the sensor image of a spectral-EXR scene (T.<nm> reflectance lit by\n"
    "  sensor.illuminant, or S0.<nm> radiance; Z depth in metres; optional mask)\n"
    "  through the configured DOE. Writes DIR/sensor.exr, DIR/sensor.png,\n"
    "  DIR/psf_atlas.png and DIR/config.json.";

}  // namespace hsd::usage
