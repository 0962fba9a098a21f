#include "model/layered_spectral_wiener.h"

#include <algorithm>
#include <string>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::model {

torch::Tensor layered_spectral_wiener_cubes(const torch::Tensor& image, const SpectralOtf& otf,
                                            const torch::Tensor& omega, const SpectralPrior& prior) {
  if (!otf.Kf.defined() || otf.Kf.dim() != 3)
    throw InputError("layered_spectral_wiener_cubes: the OTFs must keep every layer's Kf [L, K, F]");
  torch::NoGradGuard no_grad;
  const int64_t K = otf.Kf.size(1);
  std::vector<torch::Tensor> cubes;
  for (int64_t z = 0; z < K; ++z) {
    SpectralOtf one = otf;  // the layer's OTF alone: E_z[·] over one layer is that layer
    one.Kf = otf.Kf.narrow(1, z, 1);
    one.Kbar = otf.Kf.select(1, z);
    cubes.push_back(apply_spectral_wiener(spectral_wiener_filter(one, omega, prior), image));
  }
  return torch::stack(cubes, 1);
}

torch::Tensor inverse_depth_layer_weights(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m) {
  if (depth_m.dim() != 4 || depth_m.size(1) != 1)
    throw InputError("inverse_depth_layer_weights: depth must be [B, 1, H, W], got " + c10::str(depth_m.sizes()));
  if (layer_depths_m.empty()) throw InputError("inverse_depth_layer_weights: no layers");
  std::vector<double> u;
  for (double z : layer_depths_m) {
    if (!(z > 0) || !std::isfinite(z)) throw InputError("inverse_depth_layer_weights: layer depths must be finite and > 0");
    u.push_back(1.0 / z);
  }
  const int64_t K = int64_t(u.size());
  const torch::Tensor d = depth_m.detach().to(torch::kFloat64);
  if (!torch::isfinite(d).all().item<bool>() || !(d > 0).all().item<bool>())
    throw InputError("inverse_depth_layer_weights: the depth map must be finite and > 0");
  if (K == 1) return torch::ones_like(depth_m, torch::kFloat32);
  // layers ordered by inverse depth, weights returned in the given order
  std::vector<int64_t> order(static_cast<size_t>(K), 0);
  for (int64_t k = 0; k < K; ++k) order[size_t(k)] = k;
  std::sort(order.begin(), order.end(), [&](int64_t a, int64_t b) { return u[size_t(a)] < u[size_t(b)]; });
  for (int64_t k = 1; k < K; ++k)
    if (!(u[size_t(order[size_t(k)])] > u[size_t(order[size_t(k - 1)])]))
      throw InputError("inverse_depth_layer_weights: layer depths must be distinct");
  const torch::Tensor inv = 1.0 / d;  // [B, 1, H, W]
  std::vector<torch::Tensor> w(static_cast<size_t>(K));
  for (int64_t i = 0; i < K; ++i) {
    const double c = u[size_t(order[size_t(i)])];
    torch::Tensor h = torch::zeros_like(inv);
    if (i > 0) {  // rising from the previous layer
      const double a = u[size_t(order[size_t(i - 1)])];
      h = h + ((inv - a) / (c - a)).clamp(0.0, 1.0) * (inv <= c);
    } else {
      h = h + (inv <= c).to(inv.scalar_type());
    }
    if (i + 1 < K) {  // falling to the next layer
      const double b = u[size_t(order[size_t(i + 1)])];
      h = h + ((b - inv) / (b - c)).clamp(0.0, 1.0) * (inv > c);
    } else {
      h = h + (inv > c).to(inv.scalar_type());
    }
    w[size_t(order[size_t(i)])] = h;
  }
  return torch::cat(w, 1).to(torch::kFloat32);
}

torch::Tensor blend_layer_cubes(const torch::Tensor& cubes, const torch::Tensor& weights) {
  if (cubes.dim() != 5 || weights.dim() != 4 || cubes.size(0) != weights.size(0) || cubes.size(1) != weights.size(1) ||
      cubes.size(3) != weights.size(2) || cubes.size(4) != weights.size(3))
    throw InputError("blend_layer_cubes: cubes must be [B, K, L, H, W] and weights [B, K, H, W], got " +
                     c10::str(cubes.sizes()) + " and " + c10::str(weights.sizes()));
  return (cubes * weights.to(cubes.scalar_type()).unsqueeze(2)).sum(1);
}

}  // namespace hsd::model
