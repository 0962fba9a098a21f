#include "optics/sensor_noise.h"

#include <cmath>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {

torch::Tensor apply_sensor_noise(const torch::Tensor& image, const NoiseModel& m, const NoiseRng& rng) {
  if (image.dim() != 4) throw InputError("sensor noise: image must be [B, C, H, W], got " + c10::str(image.sizes()));
  torch::Tensor j = image;
  const int64_t B = image.size(0);
  if (!rng.per_image.empty() && int64_t(rng.per_image.size()) != B)
    throw InputError("sensor noise: " + std::to_string(rng.per_image.size()) + " per-image generators for a batch of " +
                     std::to_string(B));
  if (m.std_max > 0.0 || m.photons_at_saturation > 0.0) {
    const auto opts = image.options().requires_grad(false);
    // u [B, 1, 1, 1] (σ of each image) and ε [B, C, H, W].
    torch::Tensor u, eps;
    if (rng.per_image.empty()) {
      if (m.std_max > 0.0) u = torch::rand({B, 1, 1, 1}, rng.batch, opts);
      eps = torch::randn(j.sizes(), rng.batch, opts);
    } else {
      std::vector<torch::Tensor> us, es;
      for (int64_t i = 0; i < B; ++i) {
        const c10::optional<at::Generator> g = rng.per_image[size_t(i)];
        if (m.std_max > 0.0) us.push_back(torch::rand({1, 1, 1, 1}, g, opts));
        es.push_back(torch::randn({1, j.size(1), j.size(2), j.size(3)}, g, opts));
      }
      if (m.std_max > 0.0) u = torch::cat(us);
      eps = torch::cat(es);
    }
    torch::Tensor var = torch::zeros_like(j);
    if (m.std_max > 0.0) {
      const double lo = m.std_min < 0.0 ? m.std_max : m.std_min;
      const torch::Tensor sigma = lo + (m.std_max - lo) * u;  // one σ per image
      var = var + sigma.pow(2);
    }
    if (m.photons_at_saturation > 0.0) var = var + j.clamp_min(0.0) / m.photons_at_saturation;
    // +1e-30 keeps the gradient of sqrt finite where the variance is 0.
    j = j + torch::sqrt(var + 1e-30) * eps;
  }
  if (m.saturation > 0.0) j = j.clamp(0.0, m.saturation);
  if (m.bit_depth > 0) {
    const double levels = std::ldexp(1.0, int(m.bit_depth)) - 1.0;
    const double step = m.saturation / levels;
    const torch::Tensor q = torch::round(j.detach() / step) * step;
    j = j + (q - j.detach());  // straight-through
  }
  return j;
}

}  // namespace hsd::optics
