// hsd_reconstruct --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_reconstruct --model reconstructor.pt --input IMAGE [--tile 512 --overlap 32]\n"
    "                [--context C] [--precision float32|bfloat16] --out DIR\n"
    "  IMAGE: linear RGB OpenEXR (channels R, G, B) or 8/16-bit PNG (sRGB, decoded\n"
    "  to linear). Writes DIR/hs.exr (S0.<nm> channels), DIR/depth.exr (Z, metres),\n"
    "  DIR/hs_srgb.png and DIR/depth.png. Tiles of --tile pixels with --overlap\n"
    "  pixels blended on each side and --context pixels of input around each tile\n"
    "  (multiples of 32; default 2*overlap in float32, overlap in bfloat16). --precision bfloat16 runs\n"
    "  the network in bfloat16 (several times faster on CPUs with native bfloat16,\n"
    "  ~0.3% mean difference; hsd_bench reconstruct measures it); outputs stay float32.";

}  // namespace hsd::usage
