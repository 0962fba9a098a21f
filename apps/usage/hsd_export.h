// hsd_export --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_export --config FILE --checkpoint CKPT [--set key=VALUE ...] --out DIR\n"
    "  Writes DIR/reconstructor.pt (TorchScript: forward(x [B, 3, H, W] linear RGB)\n"
    "  -> (hs [B, L, H, W], depth [B, 1, H, W] metres); attributes wavelengths_m,\n"
    "  depth_range_m, camera, doe_init, config_sha, hsd_version), DIR/doe_height.pt,\n"
    "  DIR/psf_atlas.png and DIR/config.json.";

}  // namespace hsd::usage
