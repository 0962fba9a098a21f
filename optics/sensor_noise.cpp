#include "optics/sensor_noise.h"

#include <cmath>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {

torch::Tensor apply_sensor_noise(const torch::Tensor& image, const NoiseModel& m,
                                 c10::optional<at::Generator> generator) {
  if (image.dim() != 4) throw InputError("sensor noise: image must be [B, C, H, W], got " + c10::str(image.sizes()));
  torch::Tensor j = image;
  const int64_t B = image.size(0);
  if (m.std_max > 0.0 || m.photons_at_saturation > 0.0) {
    torch::Tensor var = torch::zeros_like(j);
    if (m.std_max > 0.0) {
      const double lo = m.std_min < 0.0 ? m.std_max : m.std_min;
      const torch::Tensor u = torch::rand({B, 1, 1, 1}, generator, image.options().requires_grad(false));
      const torch::Tensor sigma = lo + (m.std_max - lo) * u;  // one σ per image
      var = var + sigma.pow(2);
    }
    if (m.photons_at_saturation > 0.0) var = var + j.clamp_min(0.0) / m.photons_at_saturation;
    const torch::Tensor eps = torch::randn(j.sizes(), generator, image.options().requires_grad(false));
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
