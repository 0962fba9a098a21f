// Small builders shared by the tests: PSF specs on tiny grids.
#pragma once
#include <string>
#include <vector>

#include <torch/torch.h>

#include "common/config.h"
#include "optics/psf.h"

namespace hsd::test {

inline std::string source_path(const std::string& rel) { return std::string(HSD_SOURCE_DIR) + "/" + rel; }

// A spec with explicit geometry; indices constant unless given.
inline optics::PsfSpec make_spec(std::vector<double> wavelengths_m, std::vector<double> depths_m, int64_t n,
                                 double doe_pitch_m, double aperture_m, int64_t psf_size, double pixel_pitch_m,
                                 double sensor_distance_m, int nodes, c10::ScalarType dtype = torch::kFloat64,
                                 double refractive_index = 1.5) {
  optics::PsfSpec s;
  s.wavelengths_m = std::move(wavelengths_m);
  s.depths_m = std::move(depths_m);
  s.refractive_index.assign(s.wavelengths_m.size(), refractive_index);
  s.pixel_nodes.assign(s.wavelengths_m.size(), nodes);
  s.doe_samples = n;
  s.doe_pitch_m = doe_pitch_m;
  s.aperture_diameter_m = aperture_m;
  s.psf_size = psf_size;
  s.pixel_pitch_m = pixel_pitch_m;
  s.sensor_distance_m = sensor_distance_m;
  s.real_dtype = dtype;
  return s;
}

// Centroid (x = column, y = row) of a [P, P] image in pixels from the centre.
inline std::pair<double, double> centroid(const torch::Tensor& img) {
  const int64_t P = img.size(0);
  const torch::Tensor c = torch::arange(P, torch::kFloat64) - double(P / 2);
  const torch::Tensor w = img.to(torch::kFloat64);
  const double tot = w.sum().item<double>();
  return {(w.sum(0) * c).sum().item<double>() / tot, (w.sum(1) * c).sum().item<double>() / tot};
}

}  // namespace hsd::test
