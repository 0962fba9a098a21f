#include "data/illuminant_augment.h"

#include <torch/torch.h>

#include "common/error.h"
#include "optics/spectrum.h"

namespace hsd::data {

IlluminantBank::IlluminantBank(const std::vector<std::string>& names, const std::vector<double>& wavelengths_m,
                               double band_width_m)
    : names_(names) {
  if (names.empty()) input_error("config key data.illuminants", "needs at least one illuminant");
  std::vector<torch::Tensor> rows;
  for (size_t i = 0; i < names.size(); ++i)
    rows.push_back(optics::illuminant_bands(names[i], wavelengths_m, band_width_m,
                                            "data.illuminants[" + std::to_string(i) + "]"));
  spectra_ = torch::stack(rows);
}

torch::Tensor light_reflectance(const torch::Tensor& reflectance, const torch::Tensor& illuminant, double scale) {
  const int64_t L = illuminant.size(0);
  const int64_t band_dim = reflectance.dim() == 4 ? 1 : 0;
  if ((reflectance.dim() != 3 && reflectance.dim() != 4) || reflectance.size(band_dim) != L)
    throw InputError("reflectance must be [L, H, W] or [B, L, H, W] with L = " + std::to_string(L) + ", got " +
                     c10::str(reflectance.sizes()));
  std::vector<int64_t> shape(size_t(reflectance.dim()), 1);
  shape[size_t(band_dim)] = L;
  return reflectance * (illuminant.to(reflectance.dtype()).view(shape) * scale);
}

Lighting draw_lighting(std::mt19937_64& rng, int64_t illuminants, double lo, double hi) {
  Lighting l;
  l.illuminant = std::uniform_int_distribution<int64_t>(0, illuminants - 1)(rng);
  l.scale = std::uniform_real_distribution<double>(lo, hi)(rng);
  return l;
}

}  // namespace hsd::data
