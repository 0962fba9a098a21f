// Preview pictures: linear RGB -> sRGB-encoded 8-bit PNG (IEC 61966-2-1 transfer
// curve), written atomically.
#pragma once
#include <string>

#include <torch/types.h>

namespace hsd::data {

// The IEC 61966-2-1 decoding: sRGB-encoded values in [0, 1] -> linear, any shape.
torch::Tensor srgb_to_linear(const torch::Tensor& encoded);

// rgb float [3, H, W], linear; values are clipped to [0, white] and scaled by 1/white.
void write_srgb_png(const std::string& path, const torch::Tensor& rgb, double white = 1.0);

}  // namespace hsd::data
