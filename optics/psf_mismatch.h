// How far measured PSFs are from the simulated ones of the configured DOE
// (hsd_calibrate's mismatch report; the paper: fabricated PSFs show long tails
// and lower contrast). Per (band, depth), for measured M and simulated S
// [P, P], each summing to 1:
//   rel_l1          Σ|M − S| / Σ|S|
//   centroid_shift  centroid(M) − centroid(S) in pixels (row, col)
//   tail            the light outside the core: 1 − (energy within r80 of the
//                   slice's own centroid), r80 the radius holding 80 % of S
//                   around its centroid (so tail(S) ≈ 0.2; a fabricated
//                   DOE's long tail shows as tail(M) > tail(S))
#pragma once
#include <torch/types.h>

namespace hsd::optics {

struct PsfMismatch {
  torch::Tensor rel_l1;             // float64 [L, Z]
  torch::Tensor centroid_shift_px;  // float64 [L, Z, 2] (row, col)
  torch::Tensor tail_measured;      // float64 [L, Z]
  torch::Tensor tail_simulated;     // float64 [L, Z]
  torch::Tensor core_radius_px;     // float64 [L, Z], r80 of S
};

// measured, simulated: [L, Z, P, P].
PsfMismatch compare_psfs(const torch::Tensor& measured, const torch::Tensor& simulated);

}  // namespace hsd::optics
