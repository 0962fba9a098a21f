#include "optics/aperture.h"

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {

torch::Tensor centred_coordinates(int64_t n, double pitch_m) {
  return (torch::arange(n, torch::kFloat64) - 0.5 * double(n - 1)) * pitch_m;
}

torch::Tensor aperture_transmission(int64_t n, double pitch_m, double diameter_m, ApertureShape shape) {
  const int64_t ss = 8;
  // sub-sample coordinates: cell j spans [x_j − δ/2, x_j + δ/2]
  const torch::Tensor sub = (torch::arange(n * ss, torch::kFloat64) + 0.5) / double(ss) - 0.5 * double(n);
  const torch::Tensor x = sub * pitch_m;  // [N·ss]
  const double r = 0.5 * diameter_m;
  if (shape == ApertureShape::square) {
    const torch::Tensor inside = (x.abs() <= r).to(torch::kFloat64).view({n, ss}).mean(1);  // [N]
    return torch::outer(inside, inside);
  }
  // A cell's value is the mean over its ss×ss sub-samples of [x_a² + y_b² ≤ r²].
  // Rounding is monotone, so a cell whose farthest sub-sample sum is inside is
  // wholly inside and one whose nearest is outside wholly outside: only the
  // edge cells (≈ 4·D/δ of them, not N²) are sub-sampled, with the same float
  // sums as the full ss·N × ss·N grid would use, so the result is bitwise the
  // same (tests/optics/test_psf_closed_forms.cpp) at a fraction of its cost (the full
  // grid is 16.7 M samples at N = 512: ~0.1 s of every simulator's set-up).
  const double r2 = r * r;
  const torch::Tensor x2 = x.pow(2).view({n, ss});  // [N, ss]: squared sub-sample coordinates per cell
  const torch::Tensor near = std::get<0>(x2.min(1)), far = std::get<0>(x2.max(1));  // [N]
  torch::Tensor a = ((far.view({-1, 1}) + far.view({1, -1})) <= r2).to(torch::kFloat64);  // [N, N]: wholly inside
  const torch::Tensor edge = (((near.view({-1, 1}) + near.view({1, -1})) <= r2) & (a < 0.5)).nonzero();  // [E, 2]
  if (edge.size(0) > 0) {
    const torch::Tensor iy = edge.select(1, 0), ix = edge.select(1, 1);
    const torch::Tensor sums = x2.index_select(0, iy).unsqueeze(2) + x2.index_select(0, ix).unsqueeze(1);  // [E, ss, ss]
    a.index_put_({iy, ix}, (sums <= r2).to(torch::kFloat64).mean({1, 2}));
  }
  return a;
}

}  // namespace hsd::optics
