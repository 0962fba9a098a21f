// The spectral Wiener cube with the depth read: one LMMSE cube per rendering
// layer (spectral_wiener.h with the layer's OTF alone, H_z instead of the
// mixture over z), weighted per pixel by what a depth map says,
//   x̂(p) = Σ_z w_z(p) x̂_z(p),   x̂_z = LMMSE of x given y = H_z x + n.
// The image formation (optics/sensor_image.h, the paper's Eq. 2) makes each
// pixel of layer z the scene convolved with that layer's PSF, so inside a
// region of one layer, away from its edges, x̂_z inverts the model that made
// the image, where the mixture hedges over every layer's blur.
// Weights: with the true depth, one-hot on the layer the renderer put the
// pixel in (nearest in inverse depth: hsd_eval's depth-known reference); with
// an estimated depth, hat functions in inverse depth (the layers are spaced
// linearly in it), the nearer of the two neighbouring layers weighted more,
// a depth beyond the end layers on the end layer.
#pragma once
#include <vector>

#include <torch/types.h>

#include "model/spectral_wiener.h"

namespace hsd::model {

// image [B, 3, H, W], otf of K layers (spectral_otf, its Kf kept), omega
// [3, L], prior, weights [B, K, H, W] -> Σ_z w_z x̂_z [B, L, H, W] in the
// image's precision. One layer's filter at a time, accumulated (no
// [B, K, L, H, W] stack); a layer whose weights are all zero is left out.
// No gradient (an evaluation-time estimate).
torch::Tensor layered_spectral_wiener_cube(const torch::Tensor& image, const SpectralOtf& otf, const torch::Tensor& omega,
                                           const SpectralPrior& prior, const torch::Tensor& weights);

// layer index [B, 1, H, W] (int64 in [0, K), as optics::nearest_layer gives)
// -> one-hot weights [B, K, H, W] float32. InputError on an index outside.
torch::Tensor one_hot_layer_weights(const torch::Tensor& layer_index, int64_t K);

// depth_m [B, 1, H, W] metres (finite, > 0, else InputError), layer_depths_m
// the K rendering layers (distinct, > 0) -> weights [B, K, H, W] (float32,
// ≥ 0, summing to 1 per pixel): hat functions in inverse depth.
torch::Tensor inverse_depth_layer_weights(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m);

}  // namespace hsd::model
