#include "data/reflectance_library.h"

#include <torch/torch.h>

#include "common/error.h"
#include "optics/spectrum.h"

namespace hsd::data {

ReflectanceLibrary::ReflectanceLibrary(const std::vector<double>& wavelengths_m, double band_width_m) {
  const std::string file = optics::spectra_path("colorchecker_reflectance.csv");
  const optics::SpectralTable t = optics::SpectralTable::load_csv(file);
  const double half_nm = 0.5 * band_width_m * 1e9;
  std::vector<torch::Tensor> rows;
  for (const auto& c : t.columns()) {
    std::vector<double> v;
    for (double w : wavelengths_m) v.push_back(t.band_mean(c, w * 1e9 - half_nm, w * 1e9 + half_nm));
    rows.push_back(torch::tensor(v, torch::kFloat64));
    names_.push_back(c);
  }
  if (names_.size() != 24) input_error(file, "expected the 24 ColorChecker patches, found " + std::to_string(names_.size()));
  patches_ = torch::stack(rows);
  mean_ = patches_.mean(0);
  // Principal components of the 24 patches; rows scaled by σ_k/√24 so that
  // standard-normal coefficients reproduce the patches' spread.
  const auto svd = torch::linalg_svd(patches_ - mean_, /*full_matrices=*/false);
  const int64_t K = std::min<int64_t>(4, int64_t(wavelengths_m.size()));
  torch::Tensor V = std::get<2>(svd).narrow(0, 0, K);
  // Singular vectors have arbitrary signs (LAPACK builds differ): make each
  // row's largest component positive, so draws are the same everywhere.
  const torch::Tensor idx = V.abs().argmax(1, true);
  V = V * torch::sign(V.gather(1, idx));
  basis_ = V * (std::get<1>(svd).narrow(0, 0, K) / std::sqrt(24.0)).view({K, 1});
}

torch::Tensor ReflectanceLibrary::patch(const std::string& name) const {
  for (size_t i = 0; i < names_.size(); ++i)
    if (names_[i] == name) return patches_[int64_t(i)];
  throw InputError("no ColorChecker patch named " + name);
}

torch::Tensor ReflectanceLibrary::draw(std::mt19937_64& rng) const {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  std::uniform_int_distribution<int64_t> pick(0, 23);
  const double kind = U(rng);
  torch::Tensor s;
  // Every draw in a named local: the order of evaluation of operands is unspecified.
  if (kind < 0.35) {
    const int64_t i = pick(rng);
    const double dim = 0.7 + 0.3 * U(rng);
    s = patches_[i] * dim;  // a patch, a little darker or as is
  } else if (kind < 0.65) {
    const double a = U(rng);
    const int64_t i = pick(rng);
    const int64_t j = pick(rng);
    s = a * patches_[i] + (1.0 - a) * patches_[j];
  } else {
    std::normal_distribution<double> N(0.0, 1.0);
    std::vector<double> c;
    for (int64_t k = 0; k < basis_.size(0); ++k) c.push_back(N(rng));
    s = mean_ + torch::mv(basis_.t(), torch::tensor(c, torch::kFloat64));
  }
  return s.clamp(0.01, 0.99);
}

}  // namespace hsd::data
