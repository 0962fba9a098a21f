// The trivial answers every learned result is reported against, on the same
// pixels (README, "Baselines"):
//   constant depth: one depth for every pixel, 1 / m̃ with m̃ the median of the
//     training split's valid inverse depths [1/m]: the constant that minimises
//     the training loss's L1 term on inverse depth over the training pixels.
//   upsampling: the spectral-upsampling cube of the sensor image
//     (model/spectral_upsampling.h), the network's residual input without the
//     network: what the U-Net adds is the difference from it.
#pragma once
#include <vector>

#include <torch/types.h>

#include "data/dataset.h"

namespace hsd::train {

// Median of 1/depth over the valid pixels (mask > 0.5) of the scenes [1/m];
// InputError when no scene has a valid pixel.
double median_inverse_depth(const std::vector<data::LoadedScene>& scenes);

// The constant-depth map: depth_m [.., H, W] of `like`'s shape, every value 1 / inv_depth [m].
torch::Tensor constant_depth_map(const torch::Tensor& like, double inv_depth_per_m);

}  // namespace hsd::train
