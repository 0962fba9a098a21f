#include "model/spectral_upsampling.h"

#include <torch/torch.h>

namespace hsd::model {

torch::Tensor spectral_upsampling_weights(const torch::Tensor& omega) {
  const torch::Tensor o = omega.t().to(torch::kFloat64);  // Ω(λ, c): [L, C]
  const torch::Tensor per_band = o.sum(1, true);          // Σ_c' Ω(λ, c')  [L, 1]
  const torch::Tensor per_channel = o.sum(0, true);       // Σ_λ' Ω(λ', c)  [1, C]
  const torch::Tensor den = per_band * per_channel;
  return torch::where(den > 0, o / den.clamp_min(1e-300), torch::zeros_like(o)).to(omega.scalar_type());
}

torch::Tensor spectral_upsample(const torch::Tensor& weights, const torch::Tensor& image) {
  const int64_t B = image.size(0), C = image.size(1), H = image.size(2), W = image.size(3), L = weights.size(0);
  // [L, C] x [C, B·H·W] per image
  const torch::Tensor x = image.permute({1, 0, 2, 3}).reshape({C, B * H * W});
  return torch::mm(weights.to(image.dtype()), x).view({L, B, H, W}).permute({1, 0, 2, 3});
}

}  // namespace hsd::model
