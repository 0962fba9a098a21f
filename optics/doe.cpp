#include "optics/doe.h"

#include <cmath>
#include <filesystem>
#include <stdexcept>

#include <torch/torch.h>

#include "common/error.h"
#include "common/tensor_io.h"
#include "optics/aperture.h"

namespace hsd::optics {

double middle_depth_m(const std::vector<double>& depths_m) {
  double inv = 0.0;
  for (double z : depths_m) inv += 1.0 / z;
  return double(depths_m.size()) / inv;
}

namespace {
torch::Tensor radius_squared(int64_t n, double pitch_m) {
  const torch::Tensor x = centred_coordinates(n, pitch_m);
  return x.view({1, -1}).pow(2) + x.view({-1, 1}).pow(2);  // [N, N], rows y, columns x
}
}  // namespace

torch::Tensor fresnel_height(int64_t n, double pitch_m, double design_wavelength_m, double design_index,
                             double design_depth_m, double sensor_distance_m) {
  const double k0 = 2.0 * M_PI / design_wavelength_m;
  const torch::Tensor phase =
      radius_squared(n, pitch_m) * (-0.5 * k0 * (1.0 / design_depth_m + 1.0 / sensor_distance_m));
  return torch::remainder(phase, 2.0 * M_PI) / (k0 * (design_index - 1.0));
}

torch::Tensor spiral_height(int64_t n, double pitch_m, double min_wavelength_m, double max_wavelength_m,
                            int64_t wings, const Material& material, double design_depth_m, double sensor_distance_m) {
  const torch::Tensor x = centred_coordinates(n, pitch_m);
  const torch::Tensor X = x.view({1, -1}).expand({n, n});
  const torch::Tensor Y = x.view({-1, 1}).expand({n, n});
  const torch::Tensor theta = torch::atan2(Y, X) + M_PI;  // [0, 2π]
  const torch::Tensor t = torch::frac(theta * (double(wings) / (2.0 * M_PI)));  // position inside a wing, [0, 1)
  const torch::Tensor lam = min_wavelength_m + t * (max_wavelength_m - min_wavelength_m);
  // η(λ) varies slowly: interpolate it linearly between the sweep's ends.
  const double n0 = material.index(min_wavelength_m), n1 = material.index(max_wavelength_m);
  const torch::Tensor eta = n0 + t * (n1 - n0);
  const torch::Tensor k = (2.0 * M_PI) / lam;
  const torch::Tensor phase = radius_squared(n, pitch_m) * k * (-0.5 * (1.0 / design_depth_m + 1.0 / sensor_distance_m));
  return torch::remainder(phase, 2.0 * M_PI) / (k * (eta - 1.0));
}

torch::Tensor random_height(int64_t n, double max_height_m, uint64_t seed) {
  auto gen = at::detail::createCPUGenerator(seed);
  return torch::rand({n, n}, gen, torch::kFloat64) * max_height_m;
}

void save_height_file(const std::string& path, const torch::Tensor& height_m, double doe_pitch_m) {
  save_tensor_dict(path, {{"height_map_m", height_m.detach().to(torch::kFloat32).cpu()},
                          {"doe_pitch_m", torch::tensor(doe_pitch_m, torch::kFloat64)}});
}

torch::Tensor load_height_file(const std::string& path, int64_t expected_n, double expected_pitch_m) {
  return height_from_dict(load_tensor_dict(path), path, expected_n, expected_pitch_m);
}

torch::Tensor height_from_dict(const TensorDict& d, const std::string& path, int64_t expected_n, double expected_pitch_m) {
  const torch::Tensor h = dict_get(d, "height_map_m", path);
  const torch::Tensor p = dict_get(d, "doe_pitch_m", path);
  if (h.dim() != 2 || h.size(0) != h.size(1) || !h.is_floating_point())
    input_error(path, "height_map_m must be a square float [N, N] tensor, got " + c10::str(h.sizes()));
  if (p.numel() != 1) input_error(path, "doe_pitch_m must be a scalar");
  const double pitch = p.item<double>();
  if (h.size(0) != expected_n || std::fabs(pitch - expected_pitch_m) > 1e-9 * expected_pitch_m)
    input_error(path, "height map is " + std::to_string(h.size(0)) + "x" + std::to_string(h.size(1)) + " at " +
                          c10::str(pitch) + " m pitch; the config wants " + std::to_string(expected_n) + "x" +
                          std::to_string(expected_n) + " at " + c10::str(expected_pitch_m) +
                          " m (optics.doe_samples, optics.doe_pitch_m)");
  if (!torch::isfinite(h).all().item<bool>()) input_error(path, "height_map_m holds NaN or Inf");
  return h.to(torch::kFloat64);
}

double one_period_height(const OpticsConfig& cfg, const Material& material) {
  return cfg.doe.design_wavelength_m / (material.index(cfg.doe.design_wavelength_m) - 1.0);
}

torch::Tensor initial_height(const OpticsConfig& cfg, const Material& material, uint64_t seed) {
  const auto& d = cfg.doe;
  const int64_t n = cfg.doe_samples;
  const double z0 = d.design_depth_m > 0.0 ? d.design_depth_m : middle_depth_m(cfg.depths_m);
  const double hmax = d.max_height_m > 0.0 ? d.max_height_m : one_period_height(cfg, material);
  switch (d.init) {
    case DoeFamily::flat:
      return torch::zeros({n, n}, torch::kFloat64);
    case DoeFamily::fresnel:
      return fresnel_height(n, cfg.doe_pitch_m, d.design_wavelength_m, material.index(d.design_wavelength_m), z0,
                            cfg.sensor_distance_m);
    case DoeFamily::spiral: {
      const auto w = cfg.wavelengths_m();
      return spiral_height(n, cfg.doe_pitch_m, w.front(), w.back(), d.spiral_wings, material, z0, cfg.sensor_distance_m);
    }
    case DoeFamily::random:
      return random_height(n, hmax, seed);
    case DoeFamily::fisher:
      if (!std::filesystem::exists(d.fisher_path))
        input_error("config key optics.doe.init",
                    "\"fisher\" needs the Fisher design at optics.doe.fisher_path = \"" + d.fisher_path +
                        "\", which does not exist; run hsd_fisher --config C --out DIR first (it writes "
                        "DIR/fisher_height.pt) or use \"file:PATH\"");
      return load_height_file(d.fisher_path, n, cfg.doe_pitch_m);
    case DoeFamily::file:
      return load_height_file(d.init_path, n, cfg.doe_pitch_m);
  }
  throw std::logic_error("initial_height: unhandled DOE family");
}

Doe::Doe(torch::Tensor initial_height_m, double max_height_m, int64_t quantization_levels, double pitch_m)
    : raw_(initial_height_m.detach().clone().set_requires_grad(true)),
      max_height_m_(max_height_m), levels_(quantization_levels), pitch_m_(pitch_m) {
  if (!(max_height_m_ > 0.0)) throw InputError("DOE: max height must be > 0");
}

torch::Tensor Doe::height() const {
  // Wrap into [0, max): remainder has gradient 1 almost everywhere.
  torch::Tensor h = torch::remainder(raw_, max_height_m_);
  if (levels_ > 0) {
    const double step = max_height_m_ / double(levels_);
    const torch::Tensor q = torch::remainder(torch::round(h.detach() / step), double(levels_)) * step;
    h = h + (q - h.detach());  // straight-through: forward q, gradient of h
  }
  return h;
}

double doe_max_height_m(const OpticsConfig& cfg, const Material& material, const torch::Tensor& height_m) {
  if (cfg.doe.max_height_m > 0.0) return cfg.doe.max_height_m;
  return std::max(one_period_height(cfg, material), height_m.max().item<double>() * (1.0 + 1e-12));
}

Doe make_doe(const OpticsConfig& cfg, const Material& material, uint64_t seed, torch::Device device) {
  const torch::Tensor h0 = initial_height(cfg, material, seed);
  return Doe(h0.to(device), doe_max_height_m(cfg, material, h0), cfg.doe.quantization_levels, cfg.doe_pitch_m);
}

}  // namespace hsd::optics
