// Pictures of spectral scenes: an sRGB rendering (CIE 1931 2° observer over
// the bands, XYZ -> linear sRGB, D65 white) and a depth map in a colour map
// (inverse depth, so the layers' spacing is even) with a labelled colour bar.
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

// spectral [L, H, W] -> linear sRGB [3, H, W]. With an illuminant [L]
// (reflectance scenes) a perfect white renders to Y = 1; without (radiance),
// a radiance of 1 in every band does.
// Out-of-gamut colours are clipped at 0 unless clip_negative is false.
torch::Tensor spectral_to_linear_srgb(const torch::Tensor& spectral, const std::vector<double>& wavelengths_m,
                                      double band_width_m, const torch::Tensor& illuminant = {}, bool clip_negative = true);

// CIE 1931 x̄ ȳ z̄ band means [3, L] (float64).
torch::Tensor cmf_bands(const std::vector<double>& wavelengths_m, double band_width_m);

// Depth [1, H, W] (metres) as a PNG: turbo colour map over 1/depth in
// [1/far_m, 1/near_m], invalid pixels (mask < 0.5) black, colour bar with
// labels in metres on the right. Written atomically.
void write_depth_png(const std::string& path, const torch::Tensor& depth_m, const torch::Tensor& mask, double near_m,
                     double far_m);

}  // namespace hsd::data
