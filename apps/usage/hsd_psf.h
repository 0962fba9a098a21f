// hsd_psf --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_psf --config FILE [--set key=VALUE ...] --out DIR\n"
    "  Simulates the PSF of the configured DOE for every band (optics.wavelengths_nm)\n"
    "  and depth (optics.depths_m). Writes DIR/psf.pt, DIR/psf_atlas.png, DIR/config.json.";

}  // namespace hsd::usage
