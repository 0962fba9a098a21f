// Sensor noise and read-out, applied to the noiseless image J of
// sensor_image.h, all differentiable in J (reparameterised noise):
//   J' = J + sqrt(J⁺/photons + σ²) · ε,  ε ~ N(0, 1),  σ ~ U[σ_min, σ_max] per image
// (additive Gaussian read noise and the Gaussian approximation of Poisson shot
// noise with `photons` electrons at saturation), then clipping to
// [0, saturation] and optional quantization to 2^bits − 1 levels with a
// straight-through gradient.
#pragma once
#include <optional>

#include <torch/types.h>

namespace hsd::optics {

struct NoiseModel {
  double std_min = 0.0, std_max = 0.0;  // read-noise σ range (relative to saturation)
  double photons_at_saturation = 0.0;   // 0: no shot noise
  double saturation = 1.0;              // 0: no clipping
  int64_t bit_depth = 0;                // 0: no quantization
  bool enabled() const { return std_max > 0.0 || photons_at_saturation > 0.0 || saturation > 0.0 || bit_depth > 0; }
};

// image [B, C, H, W]; the generator makes the draws reproducible.
torch::Tensor apply_sensor_noise(const torch::Tensor& image, const NoiseModel& model,
                                 c10::optional<at::Generator> generator = c10::nullopt);

}  // namespace hsd::optics
