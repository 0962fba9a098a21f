// Sensor noise and read-out, applied to the noiseless image J of
// sensor_image.h, all differentiable in J (reparameterised noise):
//   J' = J + sqrt(J⁺/photons + σ²) · ε,  ε ~ N(0, 1),  σ ~ U[σ_min, σ_max] per image
// (additive Gaussian read noise and the Gaussian approximation of Poisson shot
// noise with `photons` electrons at saturation), then clipping to
// [0, saturation] and optional quantization to 2^bits − 1 levels with a
// straight-through gradient.
#pragma once
#include <optional>
#include <vector>

#include <torch/types.h>

namespace hsd::optics {

// make_sensor_model fills it from sensor.*; a model built by hand starts with
// no read or shot noise, and its σ range means what sensor.noise_std_min's does.
struct NoiseModel {
  // Read-noise σ range (relative to saturation): σ ~ U[std_min, std_max] per
  // image; std_min < 0 (the default, as sensor.noise_std_min) = a fixed σ = std_max.
  double std_min = -1.0, std_max = 0.0;
  double photons_at_saturation = 0.0;   // 0: no shot noise
  double saturation = 1.0;              // 0: no clipping
  int64_t bit_depth = 0;                // 0: no quantization
  bool enabled() const { return std_max > 0.0 || photons_at_saturation > 0.0 || saturation > 0.0 || bit_depth > 0; }
};

// Where the noise draws come from: torch's default generator, one generator for
// the whole batch, or one generator per image. Per image, image i's draws (its
// σ, then its ε) depend on its own generator alone, so a slice of a batch gets
// exactly the noise it gets inside the whole batch: data-parallel training
// splits a batch over processes and still matches one process.
struct NoiseRng {
  c10::optional<at::Generator> batch;
  std::vector<at::Generator> per_image;
  NoiseRng() = default;
  NoiseRng(c10::nullopt_t) {}
  NoiseRng(at::Generator g) : batch(std::move(g)) {}
  NoiseRng(c10::optional<at::Generator> g) : batch(std::move(g)) {}
  NoiseRng(std::vector<at::Generator> g) : per_image(std::move(g)) {}
};

// image [B, C, H, W]; the generator(s) make the draws reproducible. With
// per-image generators there must be B of them.
torch::Tensor apply_sensor_noise(const torch::Tensor& image, const NoiseModel& model, const NoiseRng& rng = {});

}  // namespace hsd::optics
