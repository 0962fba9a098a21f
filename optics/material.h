// Dispersion of the DOE material: refractive index η(λ) from the formula
// coefficients of refractiveindex.info (data/spectra/refractive_index_materials.json).
// The DOE phase of the paper's PSF model is φ = k (η_λ − 1) h, k = 2π/λ.
// Supported formula types (λ in µm inside the formulas):
//   1 Sellmeier   n² = 1 + C1 + Σ C2i λ²/(λ² − C2i+1²)
//   2 Sellmeier-2 n² = 1 + C1 + Σ C2i λ²/(λ² − C2i+1)
//   3 Polynomial  n² = C1 + Σ C2i λ^C2i+1
//   5 Cauchy      n  = C1 + Σ C2i λ^C2i+1
#pragma once
#include <string>
#include <vector>

namespace hsd::optics {

class Material {
 public:
  // Loads `name` from the materials JSON (default: data/spectra/refractive_index_materials.json).
  // InputError naming the config key optics.material for an unknown name.
  static Material load(const std::string& name, const std::string& json_path = "");
  // Builds a material of constant index (tests, idealised studies).
  static Material constant(double n);

  const std::string& name() const { return name_; }
  // η at wavelength λ [m]. Evaluates the formula also outside its valid range
  // (see in_valid_range); throws InputError if the formula gives n² ≤ 0 there.
  double index(double wavelength_m) const;
  bool in_valid_range(double wavelength_m) const;

  // η at each wavelength; warns once per call naming the bands outside the
  // formula's valid range.
  std::vector<double> indices(const std::vector<double>& wavelengths_m) const;

 private:
  std::string name_;
  int formula_ = 0;
  std::vector<double> c_;
  double valid_um_[2] = {0.0, 1e9};
  double constant_ = 0.0;
};

}  // namespace hsd::optics
