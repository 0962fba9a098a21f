// The spectral Wiener cube with the depth read: one LMMSE cube per rendering
// layer (spectral_wiener.h with the layer's OTF alone, H_z instead of the
// mixture over z), blended per pixel by weights a depth map gives,
//   x̂(p) = Σ_z w_z(p) x̂_z(p),   x̂_z = LMMSE of x given y = H_z x + n.
// The image formation (optics/sensor_image.h, the paper's Eq. 2) makes each
// pixel of layer z the whole scene convolved with that layer's PSF, so a
// region of one layer is exactly the single-layer model x̂_z inverts, and the
// mixture's hedge over every layer's blur (spectral_wiener.h) is lost detail
// where the depth is known. The weights are hat functions in inverse depth
// (the layers are spaced linearly in it): a depth between two layers splits
// between them in proportion to its distance, a depth beyond the end layers
// goes to the end layer; a map at a layer's depth picks that layer's cube.
#pragma once
#include <vector>

#include <torch/types.h>

#include "model/spectral_wiener.h"

namespace hsd::model {

// image [B, 3, H, W], otf of K layers (spectral_otf, its Kf kept), omega [3, L],
// prior -> the K single-layer cubes [B, K, L, H, W] in the image's precision.
// No gradient is taken through the K filters here (the depth-read base is an
// evaluation-time estimate).
torch::Tensor layered_spectral_wiener_cubes(const torch::Tensor& image, const SpectralOtf& otf,
                                            const torch::Tensor& omega, const SpectralPrior& prior);

// depth_m [B, 1, H, W] metres (finite, > 0, else InputError), layer_depths_m
// the K rendering layers (distinct, > 0) -> weights [B, K, H, W] (float32,
// ≥ 0, summing to 1 per pixel): hat functions in inverse depth.
torch::Tensor inverse_depth_layer_weights(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m);

// cubes [B, K, L, H, W], weights [B, K, H, W] -> Σ_z w_z x̂_z [B, L, H, W].
torch::Tensor blend_layer_cubes(const torch::Tensor& cubes, const torch::Tensor& weights);

}  // namespace hsd::model
