// Residual spectral upsampling (Baek et al. 2021, "Residual Learning with
// Spectral Upsampling"): a first guess of the cube from the sensor image,
//   I_up(λ) = Σ_c w(λ, c) J_c,   w(λ, c) = Ω(λ, c) / (Σ_c' Ω(λ, c') · Σ_λ' Ω(λ', c)),
// which the hyperspectral decoder's output is added to. A band no channel sees
// (Σ_c Ω = 0) gets weight 0 (guarded division).
#pragma once
#include <torch/types.h>

namespace hsd::model {

// omega [C, L] (camera response, rows R, G, B) -> w [L, C].
torch::Tensor spectral_upsampling_weights(const torch::Tensor& omega);

// w [L, C], J [B, C, H, W] -> I_up [B, L, H, W].
torch::Tensor spectral_upsample(const torch::Tensor& weights, const torch::Tensor& image);

}  // namespace hsd::model
