#include "optics/material.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/error.h"
#include "common/log.h"
#include "optics/spectrum.h"

namespace hsd::optics {

Material Material::load(const std::string& name, const std::string& json_path) {
  const std::string path = json_path.empty() ? spectra_path("refractive_index_materials.json") : json_path;
  std::ifstream f(path);
  if (!f) input_error(path, "cannot open the materials table");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(f);
  } catch (const std::exception&) {
    input_error(path, "invalid JSON");
  }
  if (!j.contains("materials") || !j["materials"].contains(name)) {
    std::string known;
    if (j.contains("materials"))
      for (auto it = j["materials"].begin(); it != j["materials"].end(); ++it) known += (known.empty() ? "" : ", ") + it.key();
    input_error("config key optics.material", "unknown material \"" + name + "\" (known: " + known + ")");
  }
  const auto& m = j["materials"][name];
  Material mat;
  mat.name_ = name;
  try {
    mat.formula_ = m.at("formula_type").get<int>();
    mat.c_ = m.at("coefficients").get<std::vector<double>>();
    const auto r = m.at("valid_range_um").get<std::vector<double>>();
    mat.valid_um_[0] = r.at(0);
    mat.valid_um_[1] = r.at(1);
  } catch (const std::exception&) {
    input_error(path, "material \"" + name + "\" lacks formula_type, coefficients or valid_range_um");
  }
  if (mat.formula_ != 1 && mat.formula_ != 2 && mat.formula_ != 3 && mat.formula_ != 5)
    input_error(path, "material \"" + name + "\": unsupported formula type " + std::to_string(mat.formula_));
  if (mat.c_.empty() || (mat.c_.size() % 2) != 1)
    input_error(path, "material \"" + name + "\": expected an odd number of coefficients");
  return mat;
}

Material Material::constant(double n) {
  Material m;
  m.name_ = "constant_" + std::to_string(n);
  m.formula_ = 0;
  m.constant_ = n;
  return m;
}

double Material::index(double wavelength_m) const {
  if (formula_ == 0) return constant_;
  const double L = wavelength_m * 1e6;  // µm
  const double L2 = L * L;
  double v = 0.0;
  switch (formula_) {
    case 1:
      v = 1.0 + c_[0];
      for (size_t i = 1; i + 1 < c_.size(); i += 2) v += c_[i] * L2 / (L2 - c_[i + 1] * c_[i + 1]);
      break;
    case 2:
      v = 1.0 + c_[0];
      for (size_t i = 1; i + 1 < c_.size(); i += 2) v += c_[i] * L2 / (L2 - c_[i + 1]);
      break;
    case 3:
      v = c_[0];
      for (size_t i = 1; i + 1 < c_.size(); i += 2) v += c_[i] * std::pow(L, c_[i + 1]);
      break;
    case 5: {
      double n = c_[0];
      for (size_t i = 1; i + 1 < c_.size(); i += 2) n += c_[i] * std::pow(L, c_[i + 1]);
      if (!(n > 1.0) || !std::isfinite(n))
        input_error("optics.material " + name_, "formula gives n = " + std::to_string(n) + " at " + std::to_string(L) + " um");
      return n;
    }
  }
  if (!(v > 1.0) || !std::isfinite(v))
    input_error("optics.material " + name_, "formula gives n^2 = " + std::to_string(v) + " at " + std::to_string(L) + " um (a pole or outside any sensible range)");
  return std::sqrt(v);
}

bool Material::in_valid_range(double wavelength_m) const {
  const double L = wavelength_m * 1e6;
  return formula_ == 0 || (L >= valid_um_[0] - 1e-12 && L <= valid_um_[1] + 1e-12);
}

std::vector<double> Material::indices(const std::vector<double>& wavelengths_m) const {
  std::vector<double> out;
  std::ostringstream outside;
  for (double w : wavelengths_m) {
    out.push_back(index(w));
    if (!in_valid_range(w)) outside << (outside.tellp() > 0 ? ", " : "") << w * 1e9 << " nm";
  }
  if (outside.tellp() > 0)
    log::warn("material " + name_ + ": bands " + outside.str() + " lie outside the dispersion formula's valid range (" +
              std::to_string(valid_um_[0] * 1e3) + "-" + std::to_string(valid_um_[1] * 1e3) + " nm); extrapolating");
  return out;
}

}  // namespace hsd::optics
