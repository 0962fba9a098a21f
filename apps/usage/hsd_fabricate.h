// hsd_fabricate --help: shared by the app and its launcher (apps/launcher.cpp),
// which prints it without loading LibTorch.
#pragma once

namespace hsd::usage {

inline constexpr const char* kText =
    "hsd_fabricate --config FILE --doe FILE [--tolerance] [--set key=VALUE ...] --out DIR\n"
    "  A DOE for the fab (docs/fabrication.md). --doe: a training checkpoint or a\n"
    "  height-map file (hsd_export's doe_height.pt, hsd_fisher's fisher_height.pt) on\n"
    "  the config's DOE grid. Writes DIR/height_map.png and .tif (16-bit, 0 = no\n"
    "  material, 65535 = height_map.json's max_height_m; the design's heights for a\n"
    "  grayscale process), DIR/height_map.json (pitch, height scale, levels, material,\n"
    "  orientation), DIR/mask_<k>.png for k = 0 .. log2(K)-1 (the K-level binary\n"
    "  process, K = fabrication.levels: 255 = the cells whose level has bit k set),\n"
    "  DIR/masks.gds (GDSII: user unit 1 um, database unit 1 nm, layer k+1 = mask k,\n"
    "  cell fabrication.cell_name), DIR/fabrication.json and .md (features against\n"
    "  fabrication.min_feature_m, height histogram, quantisation error and its PSF\n"
    "  change), DIR/fabrication.png.\n"
    "  --tolerance: also sweeps the errors a fab makes (fabrication.tolerance: etch\n"
    "  depth, white and correlated roughness, mask misalignment, edge rounding,\n"
    "  decentre), each against the fabricated design without error: PSF change,\n"
    "  point-source CRLB and, for a checkpoint with its dataset, HS PSNR and depth\n"
    "  RMSE on the test split; then fabrication.tolerance.draws random draws of the\n"
    "  errors together (drawn as train.fabrication_noise draws them, from\n"
    "  fabrication.tolerance.draw_scales; the same draws for every DOE), their\n"
    "  losses as mean +- SD. Writes DIR/tolerance.json, .md and .png.";

}  // namespace hsd::usage
