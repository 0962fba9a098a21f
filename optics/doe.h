// The diffractive optical element: height-map families (optics.doe.init), the
// height-map file format, and the constraints applied to a learnable height map.
// Heights are metres on the DOE grid, float64 [N, N], sample [i, j] at
// x = (j − (N−1)/2)·δ, y = (i − (N−1)/2)·δ (optics/conventions.h).
#pragma once
#include <string>

#include <torch/types.h>

#include "common/config.h"
#include "common/tensor_io.h"
#include "optics/material.h"

namespace hsd::optics {

// Middle of the depth range in inverse depth: 1 / mean(1/z).
double middle_depth_m(const std::vector<double>& depths_m);

// Kinoform (Fresnel) lens imaging a source at z0 onto the sensor at s for λ0:
// phase −k0 r² (1/z0 + 1/s)/2 wrapped to [0, 2π), height = phase / (k0 (η0 − 1)),
// so h ∈ [0, λ0/(η0 − 1)). Its focal length at λ is f(λ) = f0 λ0/λ.
torch::Tensor fresnel_height(int64_t n, double pitch_m, double design_wavelength_m, double design_index,
                             double design_depth_m, double sensor_distance_m);

// Diffracted-rotation ("spiral") DOE after Jeon et al., SIGGRAPH 2019: the grid
// is divided into `wings` equal azimuthal sectors; inside each, the design
// wavelength sweeps linearly with azimuth from λ_min to λ_max, and the height is
// the kinoform of fresnel_height at that wavelength. Each wavelength focuses
// through the part of every wing designed for it, so the PSF is an anisotropic
// pattern that rotates with λ.
torch::Tensor spiral_height(int64_t n, double pitch_m, double min_wavelength_m, double max_wavelength_m,
                            int64_t wings, const Material& material, double design_depth_m, double sensor_distance_m);

// Independent uniform heights in [0, max_height_m), seeded.
torch::Tensor random_height(int64_t n, double max_height_m, uint64_t seed);

// Height-map file (docs/formats.md): dict {height_map_m float32 [N, N], doe_pitch_m float64}.
void save_height_file(const std::string& path, const torch::Tensor& height_m, double doe_pitch_m);
// Loads and checks it against the expected grid; InputError naming the file otherwise.
torch::Tensor load_height_file(const std::string& path, int64_t expected_n, double expected_pitch_m);
// The same from a dict already read from `path` (e.g. a checkpoint, whose other entries the caller wants too).
torch::Tensor height_from_dict(const TensorDict& d, const std::string& path, int64_t expected_n, double expected_pitch_m);

// The initial height map named by cfg.doe.init (float64 [N, N]).
torch::Tensor initial_height(const OpticsConfig& cfg, const Material& material, uint64_t seed);

// Default maximum height: one 2π period at the design wavelength, λ0/(η(λ0) − 1).
double one_period_height(const OpticsConfig& cfg, const Material& material);

// The period H of a height map's wrap (and of its levels): optics.doe.max_height_m,
// or the larger of one period and the map's own maximum so a design is never cut.
double doe_max_height_m(const OpticsConfig& cfg, const Material& material, const torch::Tensor& height_m);

// Learnable height map with the fabrication constraints of the config:
// heights wrap into [0, max_height) (a 2π phase wrap at the design wavelength,
// gradient 1) and, with K quantization levels, are rounded to multiples of
// max_height/K with a straight-through gradient.
class Doe {
 public:
  Doe(torch::Tensor initial_height_m, double max_height_m, int64_t quantization_levels, double pitch_m);
  // Raw parameter (requires grad); optimisers update this.
  torch::Tensor& parameter() { return raw_; }
  const torch::Tensor& parameter() const { return raw_; }
  // Constrained height [N, N] in metres (differentiable in parameter()).
  torch::Tensor height() const;
  double max_height_m() const { return max_height_m_; }
  double pitch_m() const { return pitch_m_; }

 private:
  torch::Tensor raw_;
  double max_height_m_;
  int64_t levels_;
  double pitch_m_;
};

// Builds the Doe of a config: initial_height, max height (config value, or the
// larger of one period and the initial map's maximum so a design is never cut).
Doe make_doe(const OpticsConfig& cfg, const Material& material, uint64_t seed, torch::Device device);

}  // namespace hsd::optics
