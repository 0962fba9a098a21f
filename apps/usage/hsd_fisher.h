// hsd_fisher --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_fisher --config FILE [--set key=VALUE ...] --out DIR\n"
    "  Computes the Cramer-Rao lower bound of inverse depth and wavelength, with the\n"
    "  point's position and brightness unknown (fisher.nuisance), for the Fresnel and\n"
    "  spiral DOEs and designs a DOE that minimises it (fisher.*: photon budget,\n"
    "  background, aggregate, basis, steps). Every design is also reported with\n"
    "  nothing unknown besides (1/z, wavelength). fisher.model=scene bounds 1/z through\n"
    "  a 1/f^2 textured scene in the camera's channels instead of a point source (only\n"
    "  the MTF carries depth there); the other bound is reported beside it.\n"
    "  Writes DIR/crlb.json, DIR/crlb.md,\n"
    "  DIR/fisher_height.pt, DIR/fisher_curve.png, DIR/psf_atlas_fisher.png and\n"
    "  DIR/config.json. Train from the design with optics.doe.init=fisher and\n"
    "  optics.doe.fisher_path=DIR/fisher_height.pt.";

}  // namespace hsd::usage
