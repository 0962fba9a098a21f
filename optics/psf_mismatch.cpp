#include "optics/psf_mismatch.h"

#include <torch/torch.h>

#include "optics/psf_calibration.h"

namespace hsd::optics {

PsfMismatch compare_psfs(const torch::Tensor& measured, const torch::Tensor& simulated) {
  const torch::Tensor M = measured.to(torch::kFloat64).cpu(), S = simulated.to(torch::kFloat64).cpu();
  const int64_t L = M.size(0), Z = M.size(1), P = M.size(2);
  PsfMismatch r;
  r.rel_l1 = (M - S).abs().sum({2, 3}) / S.abs().sum({2, 3}).clamp_min(1e-300);
  r.centroid_shift_px = torch::zeros({L, Z, 2}, torch::kFloat64);
  r.tail_measured = torch::zeros({L, Z}, torch::kFloat64);
  r.tail_simulated = torch::zeros({L, Z}, torch::kFloat64);
  r.core_radius_px = torch::zeros({L, Z}, torch::kFloat64);
  const torch::Tensor rows = torch::arange(P, torch::kFloat64).view({-1, 1}), cols = torch::arange(P, torch::kFloat64).view({1, -1});
  for (int64_t l = 0; l < L; ++l)
    for (int64_t z = 0; z < Z; ++z) {
      const auto cm = image_centroid(M[l][z]), cs = image_centroid(S[l][z]);
      r.centroid_shift_px[l][z][0] = cm.first - cs.first;
      r.centroid_shift_px[l][z][1] = cm.second - cs.second;
      const torch::Tensor rs = torch::sqrt((rows - cs.first).pow(2) + (cols - cs.second).pow(2));
      const torch::Tensor rm = torch::sqrt((rows - cm.first).pow(2) + (cols - cm.second).pow(2));
      // r80 of S: the smallest radius (over the pixel radii) holding 80 % of its light.
      const auto sorted = rs.flatten().sort();
      const torch::Tensor cum = S[l][z].flatten().index_select(0, std::get<1>(sorted)).cumsum(0) / S[l][z].sum();
      const int64_t k = std::min<int64_t>(P * P - 1, (cum < 0.8).sum().item<int64_t>());
      const double r80 = std::get<0>(sorted)[k].item<double>();
      r.core_radius_px[l][z] = r80;
      r.tail_simulated[l][z] = 1.0 - (S[l][z] * (rs <= r80)).sum().item<double>() / S[l][z].sum().item<double>();
      r.tail_measured[l][z] = 1.0 - (M[l][z] * (rm <= r80)).sum().item<double>() / M[l][z].sum().item<double>();
    }
  return r;
}

}  // namespace hsd::optics
