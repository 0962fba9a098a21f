// hsd_calibrate --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_calibrate --config FILE --captures DIR [--reference psf.pt] [--set key=VALUE ...] --out OUT\n"
    "  Measured PSFs from point-source captures: reads DIR/captures.json (docs/camera.md,\n"
    "  docs/formats.md), subtracts the dark frame,\n"
    "  removes hot pixels and the background, registers each PSF (to captures.json's\n"
    "  axis_px, or to its centroid), cuts the optics.psf_size window and normalises\n"
    "  it. Writes OUT/psf.pt (source \"measured\", with per-slice background, noise\n"
    "  and SNR; usable as optics.psf_source = \"file:OUT/psf.pt\"), OUT/mismatch.json\n"
    "  and OUT/mismatch.png against the simulated PSFs of the configured DOE\n"
    "  (--reference: also against a given stack, e.g. synthetic captures' truth).\n"
    "hsd_calibrate --config FILE --make-captures [--set key=VALUE ...] --out DIR\n"
    "  A synthetic captures folder: the configured DOE perturbed by fabrication.error,\n"
    "  imaged as point sources with calibration.synthetic's noise, background, dark\n"
    "  frame and hot pixels; also DIR/truth_psf.pt (the perturbed DOE's PSFs) and\n"
    "  DIR/perturbed_height.pt.";

}  // namespace hsd::usage
