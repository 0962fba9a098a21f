// Small scenes and wavelength lists for the data tests.
#pragma once
#include <cstdint>
#include <initializer_list>
#include <vector>

#include <torch/torch.h>

#include "common/config.h"
#include "data/scene_exr.h"

namespace hsd::test {

// Wavelengths given in nm, in metres.
inline std::vector<double> nm(std::initializer_list<double> v) {
  std::vector<double> out;
  for (double x : v) out.push_back(x * 1e-9);
  return out;
}

// A scene of H × W px with one reflectance value in every band and one depth, all valid.
inline data::SpectralScene flat_scene(const std::vector<double>& w, int64_t H, int64_t W, double value, double depth) {
  data::SpectralScene s;
  s.wavelengths_m = w;
  s.spectral = torch::full({int64_t(w.size()), H, W}, value);
  s.depth_m = torch::full({1, H, W}, depth);
  s.mask = torch::ones({1, H, W});
  return s;
}

// The generator's defaults on a 96 × 72 px frame.
inline GeneratorConfig small_generator() {
  GeneratorConfig g;
  g.width_px = 96;
  g.height_px = 72;
  return g;
}

}  // namespace hsd::test
