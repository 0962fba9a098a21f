#include "optics/leave_out.h"

#include <torch/torch.h>

namespace hsd::optics {

std::vector<int64_t> needed_bands(const torch::Tensor& radiance, const torch::Tensor& omega, double band_tol) {
  const int64_t B = radiance.size(0), L = radiance.size(1), C = omega.size(0);
  const torch::Tensor om = omega.detach().abs().to(torch::kFloat64).cpu().view({1, C, L});        // [1, C, L]
  const torch::Tensor rad = radiance.detach().abs().to(torch::kFloat64);
  const torch::Tensor peak = rad.amax({2, 3}).cpu().view({B, 1, L});                              // per image
  const torch::Tensor mean = rad.mean({2, 3}).cpu().view({B, 1, L});
  const torch::Tensor budget = (om * mean).sum(2) * band_tol;                                      // [B, C]
  const torch::Tensor bound = om * peak;                                                           // [B, C, L]
  // Darkest bands first (by their largest bound over images and channels); stop
  // at the first that does not fit every image's and channel's budget.
  const torch::Tensor order = std::get<1>(bound.amax({0, 1}).sort());
  torch::Tensor used = torch::zeros({B, C}, torch::kFloat64);
  std::vector<bool> dark(size_t(L), false);
  for (int64_t i = 0; i < L; ++i) {
    const int64_t l = order[i].item<int64_t>();
    const torch::Tensor next = used + bound.select(2, l);
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
