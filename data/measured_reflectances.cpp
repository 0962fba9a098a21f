#include "data/measured_reflectances.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <torch/torch.h>

#include "common/error.h"
#include "data/band_resample.h"
#include "data/mat_file.h"
#include "data/reflectance_library.h"
#include "optics/spectrum.h"

namespace hsd::data {

std::string MeasuredReflectances::source_path() { return optics::data_dir() + "/real/vrhel_objects/Objects_Vhrel.mat"; }

namespace {
// Shape distances [M, 24] of rows of S [M, L] to the patches P [24, L]:
// ‖s − a·p‖ / ‖s‖ for the best scale a >= 0, the sine of the spectral angle.
torch::Tensor shape_distances(const torch::Tensor& S, const torch::Tensor& P) {
  const torch::Tensor cos = S.mm(P.t()) / (S.norm(2, 1, true) * P.norm(2, 1).view({1, -1})).clamp_min(1e-30);
  return (1.0 - cos.clamp_min(0).pow(2)).clamp_min(0).sqrt();
}
}  // namespace

MeasuredReflectances::MeasuredReflectances(const std::vector<double>& wavelengths_m, double band_width_m,
                                           double exclusion, int64_t min_spectra) {
  const std::string path = source_path();
  const MatFile f = read_mat_file(path);
  const torch::Tensor data = f.at("data").tensor();                      // [31, 170]
  const torch::Tensor wl = f.at("wavelength").tensor().reshape(-1);      // [31] nm
  if (data.dim() != 2 || data.size(0) != wl.size(0) || wl.size(0) < 2)
    input_error(path, "'data' must be [wavelengths, spectra] matching 'wavelength'");
  std::vector<double> in_m;
  for (int64_t i = 0; i < wl.size(0); ++i) in_m.push_back(wl[i].item<double>() * 1e-9);
  const torch::Tensor R = band_resampling_matrix(in_m, wavelengths_m, band_width_m, path);  // [L, 31]
  const torch::Tensor all = R.mm(data).t().clamp(0.0, 1.0).contiguous();                 // [170, L]
  checker_ = ReflectanceLibrary(wavelengths_m, band_width_m).colorchecker();
  const torch::Tensor dist = std::get<0>(shape_distances(all, checker_).min(1));        // [170]
  const torch::Tensor keep = dist >= exclusion;
  excluded_ = all.size(0) - keep.sum().item<int64_t>();
  spectra_ = all.index({keep}).contiguous();
  if (spectra_.size(0) < min_spectra)
    input_error("config key data.generator.spectral_exclusion",
                "leaves " + std::to_string(spectra_.size(0)) + " of " + std::to_string(all.size(0)) + " measured spectra; a surface needs " +
                    std::to_string(min_spectra) + " (use a smaller value)");
  min_distance_ = dist.masked_select(keep).min().item<double>();
}

double MeasuredReflectances::distance_to_colorchecker(const torch::Tensor& spectrum) const {
  return shape_distances(spectrum.to(torch::kFloat64).view({1, -1}), checker_).min().item<double>();
}

torch::Tensor MeasuredReflectances::draw(std::mt19937_64& rng, int64_t k) const {
  std::vector<int64_t> idx(size_t(spectra_.size(0)));
  std::iota(idx.begin(), idx.end(), 0);
  // Partial Fisher-Yates with our own draws (std::shuffle's use of the engine is unspecified).
  k = std::min<int64_t>(k, int64_t(idx.size()));
  for (int64_t i = 0; i < k; ++i) {
    const int64_t j = std::uniform_int_distribution<int64_t>(i, int64_t(idx.size()) - 1)(rng);
    std::swap(idx[size_t(i)], idx[size_t(j)]);
  }
  idx.resize(size_t(k));
  return spectra_.index_select(0, torch::tensor(idx, torch::kLong));
}

}  // namespace hsd::data
