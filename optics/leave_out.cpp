#include "optics/leave_out.h"

#include <torch/torch.h>

namespace hsd::optics {

std::vector<int64_t> needed_bands(const torch::Tensor& radiance, const torch::Tensor& omega, double band_tol) {
  const int64_t L = radiance.size(1), C = omega.size(0);
  const torch::Tensor om = omega.detach().abs().to(torch::kFloat64).cpu();                         // [C, L]
  const torch::Tensor rad = radiance.detach().abs().to(torch::kFloat64);
  const torch::Tensor peak = rad.amax({0, 2, 3}).cpu(), mean = rad.mean({0, 2, 3}).cpu();           // [L]
  const torch::Tensor budget = (om * mean.view({1, L})).sum(1) * band_tol;                          // [C]
  const torch::Tensor bound = om * peak.view({1, L});                                               // [C, L]
  // Darkest bands first (by their largest channel bound); stop at the first that does not fit.
  const torch::Tensor order = std::get<1>(bound.amax(0).sort());
  torch::Tensor used = torch::zeros({C}, torch::kFloat64);
  std::vector<bool> dark(size_t(L), false);
  for (int64_t i = 0; i < L; ++i) {
    const int64_t l = order[i].item<int64_t>();
    const torch::Tensor next = used + bound.select(1, l);
    if (!(next <= budget).all().item<bool>()) break;
    used = next;
    dark[size_t(l)] = true;
  }
  std::vector<int64_t> bands;
  for (int64_t l = 0; l < L; ++l)
    if (!dark[size_t(l)]) bands.push_back(l);
  return bands;
}

int64_t psf_support_window(const torch::Tensor& psf, double tol) {
  const int64_t P = psf.size(-1), c = P / 2;
  const torch::Tensor p = psf.detach().to(torch::kFloat64).cpu().reshape({-1, P * P});  // [LZ, P²]
  const torch::Tensor i = torch::arange(P, torch::kInt64) - c;
  const torch::Tensor ring = torch::max(i.abs().view({P, 1}), i.abs().view({1, P})).reshape({1, P * P});  // Chebyshev radius
  const torch::Tensor by_ring = torch::zeros({p.size(0), c + 1}, torch::kFloat64).scatter_add_(1, ring.expand_as(p), p);
  const torch::Tensor total = by_ring.sum(1, true).clamp_min(1e-300);
  const torch::Tensor outside = (total - by_ring.cumsum(1)) / total;  // [LZ, c+1]: light beyond radius d
  const torch::Tensor worst = outside.amax(0);
  for (int64_t d = 0; d <= c; ++d)
    if (worst[d].item<double>() <= tol) return 2 * d + 1;
  return P;
}

}  // namespace hsd::optics
