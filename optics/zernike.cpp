#include "optics/zernike.h"

#include <cmath>
#include <cstdlib>

#include <torch/torch.h>

#include "common/error.h"
#include "optics/aperture.h"

namespace hsd::optics {

namespace {
// Noll index j -> (n, m) with m signed (cos for even j, sin for odd j when m != 0).
std::pair<int64_t, int64_t> noll_to_nm(int64_t j) {
  int64_t n = 0;
  while ((n + 1) * (n + 2) / 2 < j) ++n;
  const int64_t k = j - n * (n + 1) / 2 - 1;  // 0-based position within row n
  int64_t m = (n % 2 == 0) ? 2 * ((k + 1) / 2) : 2 * (k / 2) + 1;
  if (m != 0 && j % 2 == 1) m = -m;  // odd j: sine term
  return {n, m};
}
double factorial(int64_t k) { return std::tgamma(double(k) + 1.0); }
}  // namespace

torch::Tensor zernike(int64_t j, const torch::Tensor& rho, const torch::Tensor& theta) {
  if (j < 1) throw InputError("Zernike index must be >= 1 (Noll)");
  const auto [n, m] = noll_to_nm(j);
  const int64_t am = std::abs(m);
  torch::Tensor R = torch::zeros_like(rho);
  for (int64_t s = 0; s <= (n - am) / 2; ++s) {
    const double c = ((s % 2) ? -1.0 : 1.0) * factorial(n - s) /
                     (factorial(s) * factorial((n + am) / 2 - s) * factorial((n - am) / 2 - s));
    R = R + c * rho.pow(double(n - 2 * s));
  }
  torch::Tensor z;
  if (m == 0) z = std::sqrt(double(n + 1)) * R;
  else if (m > 0) z = std::sqrt(2.0 * double(n + 1)) * R * torch::cos(double(am) * theta);
  else z = std::sqrt(2.0 * double(n + 1)) * R * torch::sin(double(am) * theta);
  return torch::where(rho <= 1.0, z, torch::zeros_like(z));
}

torch::Tensor zernike_basis(int64_t first, int64_t count, int64_t n, double pitch_m, double diameter_m) {
  const torch::Tensor x = centred_coordinates(n, pitch_m).to(torch::kFloat64);
  const torch::Tensor X = x.view({1, -1}).expand({n, n}), Y = x.view({-1, 1}).expand({n, n});
  const torch::Tensor rho = (X.pow(2) + Y.pow(2)).sqrt() / (0.5 * diameter_m);
  const torch::Tensor theta = torch::atan2(Y, X);
  std::vector<torch::Tensor> modes;
  for (int64_t j = first; j < first + count; ++j) modes.push_back(zernike(j, rho, theta));
  return torch::stack(modes);
}

}  // namespace hsd::optics
