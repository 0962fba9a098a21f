// How fine a depth map's structure is, as a number, and real depth maps to
// compare with (hsd_scenes' realism statistics, hsd_eval's reference).
//   * The resolution oracle: the true inverse depth averaged over a w × w box
//     of valid pixels (the box clipped at the borders). It is what a depth
//     sensor exact at the scale of w pixels and blind below it would report.
//   * Depth structure of a map: the oracle's depth RMSE at a box of a fixed
//     fraction of the smaller image side (default 1/5: 29 px at 144 px),
//     over the RMSE of the map's own median inverse depth (one constant),
//     both in metres over the valid pixels. 0: the map is smooth at that
//     scale; 1: knowing depth at that scale is worth no more than a constant.
//     A learned depth map through a PSF of that size cannot be expected to
//     beat the oracle by much, so this bounds what a test set allows.
//   * Reference maps: four real indoor depth maps (TUM, SUN RGB-D, NYU v2,
//     Middlebury Aloe; data/real/README.md), resized to the generator's size
//     and mapped linearly in inverse depth onto [near, far] (their 1st..99th
//     percentiles), as hsd_import maps an uncalibrated disparity.
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

// depth_m [.., H, W] (metres), mask of the same shape (> 0.5 = valid), window
// odd >= 1 -> depth [m], same shape and dtype. Pixels with no valid neighbour
// keep their own depth; w = 1 returns the truth at valid pixels.
torch::Tensor box_oracle_depth_map(const torch::Tensor& depth_m, const torch::Tensor& mask, int64_t window_px);

// The box for `fraction` of the smaller side of an H × W map: odd, >= 1.
int64_t structure_window_px(int64_t H, int64_t W, double fraction = 0.2);

// depth_m [H, W] or [1, H, W], mask alike -> the ratio above (NaN with fewer than 2 valid pixels
// or a map whose median constant is exact).
double depth_structure(const torch::Tensor& depth_m, const torch::Tensor& mask, double fraction = 0.2);

struct ReferenceDepthMap {
  std::string name;       // e.g. "TUM RGB-D (office desk)"
  torch::Tensor depth_m;  // float32 [1, H, W]
  torch::Tensor mask;     // float32 [1, H, W], 1 = measured
};
// The four reference maps at H × W over [near_m, far_m]; InputError naming a missing or damaged file.
std::vector<ReferenceDepthMap> reference_depth_maps(int64_t H, int64_t W, double near_m, double far_m);

}  // namespace hsd::data
