// hsd_eval --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_eval --config FILE (--checkpoint CKPT | --model reconstructor.pt [--doe H.pt]) [--split test]\n"
    "         [--data DIR] [--camera-psf psf.pt] [--set key=VALUE ...] --out DIR\n"
    "  Evaluates the DOE and network of a training checkpoint on every scene of a\n"
    "  split of data.root: hyperspectral and luminance PSNR/SSIM, depth RMSE/MAE,\n"
    "  ColorChecker reflectance RMSE. Writes DIR/metrics.json, DIR/report.md and\n"
    "  pictures. With --model, the DOE is DIR_OF_MODEL/doe_height.pt (hsd_export) or --doe.\n"
    "  --data DIR evaluates another dataset (same as --set data.root=DIR), e.g. the\n"
    "  held-out real-derived set of hsd_scenes --real.\n"
    "  --camera-psf FILE images the scenes through FILE's PSF stack (e.g. a fabricated\n"
    "  DOE's, measured by hsd_calibrate) while the network and the Wiener baseline keep\n"
    "  the config's PSFs: a model evaluated through a camera that differs from it.";

}  // namespace hsd::usage
