#include "model/layered_spectral_wiener.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::model {

torch::Tensor layered_spectral_wiener_cube(const torch::Tensor& image, const SpectralOtf& otf, const torch::Tensor& omega,
                                           const SpectralPrior& prior, const torch::Tensor& weights) {
  if (!otf.Kf.defined() || otf.Kf.dim() != 3)
    throw InputError("layered_spectral_wiener_cube: the OTFs must keep every layer's Kf [L, K, F]");
  const int64_t K = otf.Kf.size(1);
  if (image.dim() != 4 || weights.dim() != 4 || weights.size(0) != image.size(0) || weights.size(1) != K ||
      weights.size(2) != image.size(2) || weights.size(3) != image.size(3))
    throw InputError("layered_spectral_wiener_cube: weights must be [B, " + std::to_string(K) +
                     ", H, W] for the image " + c10::str(image.sizes()) + ", got " + c10::str(weights.sizes()));
  torch::NoGradGuard no_grad;
  torch::Tensor out;
  for (int64_t z = 0; z < K; ++z) {
    const torch::Tensor w = weights.narrow(1, z, 1);
    if (!(w != 0).any().item<bool>()) continue;  // no pixel reads this layer
    SpectralOtf one = otf;  // the layer's OTF alone: E_z[·] over one layer is that layer
    one.Kf = otf.Kf.narrow(1, z, 1);
    one.Kbar = otf.Kf.select(1, z);
    const torch::Tensor c = apply_spectral_wiener(spectral_wiener_filter(one, omega, prior), image);
    const torch::Tensor wc = c * w.to(c.scalar_type());
    out = out.defined() ? out + wc : wc;
  }
  if (!out.defined())  // every weight zero
    out = torch::zeros({image.size(0), otf.Kf.size(0), image.size(2), image.size(3)},
                       image.options().dtype(image.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32));
  return out;
}

torch::Tensor one_hot_layer_weights(const torch::Tensor& layer_index, int64_t K) {
  if (layer_index.dim() != 4 || layer_index.size(1) != 1 || layer_index.scalar_type() != torch::kInt64 || K < 1)
    throw InputError("one_hot_layer_weights: the layer index must be int64 [B, 1, H, W] and K >= 1, got " +
                     c10::str(layer_index.sizes()));
  if (layer_index.numel() > 0 && (layer_index.min().item<int64_t>() < 0 || layer_index.max().item<int64_t>() >= K))
    throw InputError("one_hot_layer_weights: a layer index lies outside [0, " + std::to_string(K) + ")");
  return torch::zeros({layer_index.size(0), K, layer_index.size(2), layer_index.size(3)},
                      layer_index.options().dtype(torch::kFloat32))
      .scatter_(1, layer_index, 1.0);
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

}  // namespace hsd::model
