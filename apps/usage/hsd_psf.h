// hsd_psf --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_psf --config FILE [--set key=VALUE ...] --out DIR\n"
    "  Simulates the PSF of the configured DOE for every band (optics.wavelengths_nm)\n"
    "  and depth (optics.depths_m). Writes DIR/psf.pt, DIR/psf_atlas.png, DIR/config.json.\n"
    "  With optics.field_angle_deg != 0: the PSFs of a point source at that angle (window\n"
    "  on the chief ray's image point) and DIR/shift_variance.json against the on-axis PSFs.";

}  // namespace hsd::usage
