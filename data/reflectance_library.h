// Physically plausible reflectance spectra for synthetic scenes: the 24
// measured ColorChecker patches (data/spectra/colorchecker_reflectance.csv),
// band-integrated on the config's bands, and draws from them — a patch, a
// convex mixture of two patches, or a random point of the low-dimensional
// linear model fitted to the 24 (mean + 4 principal components, coefficients
// drawn with the patches' own spread), all clipped to [0.01, 0.99].
#pragma once
#include <random>
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

class ReflectanceLibrary {
 public:
  ReflectanceLibrary(const std::vector<double>& wavelengths_m, double band_width_m);
  const torch::Tensor& colorchecker() const { return patches_; }  // float64 [24, L]
  const std::vector<std::string>& patch_names() const { return names_; }
  const torch::Tensor& mean() const { return mean_; }    // [L]
  const torch::Tensor& basis() const { return basis_; }  // [K, L], rows scaled by the patches' spread
  torch::Tensor patch(const std::string& name) const;   // [L]
  // One spectrum [L], float64, in [0.01, 0.99].
  torch::Tensor draw(std::mt19937_64& rng) const;

 private:
  std::vector<std::string> names_;
  torch::Tensor patches_, mean_, basis_;
};

}  // namespace hsd::data
