// How well a PSF stack tells depths apart (optics/depth_distinctness.h): the
// point-source total-variation distance and the scene-weighted cue, each
// against a closed form.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>

#include <torch/torch.h>

#include "optics/depth_distinctness.h"

using namespace hsd;

namespace {

// [1, Z, P, P] stack with a unit point at the given (row, col) of each slice.
torch::Tensor points(int64_t P, const std::vector<std::pair<int64_t, int64_t>>& at) {
  torch::Tensor p = torch::zeros({1, int64_t(at.size()), P, P}, torch::kFloat64);
  for (size_t z = 0; z < at.size(); ++z) p[0][int64_t(z)][at[z].first][at[z].second] = 1.0;
  return p;
}

// Centred w x w box, normalised to 1.
torch::Tensor box(int64_t P, int64_t w) {
  torch::Tensor b = torch::zeros({P, P}, torch::kFloat64);
  const int64_t c = P / 2, r = w / 2;
  b.slice(0, c - r, c - r + w).slice(1, c - r, c - r + w).fill_(1.0 / double(w * w));
  return b;
}

}  // namespace

TEST_CASE("depth distinctness: total variation is 0 for the same PSF, 1 for disjoint ones, and names the pair",
          "[optics][cue]") {
  const auto d = optics::depth_distinctness(points(5, {{2, 2}, {2, 3}, {2, 2}}));
  REQUIRE(d.per_band.size() == 1);
  CHECK(d.per_band[0] == 0.0);
  CHECK(d.pair[0] == std::make_pair<int64_t, int64_t>(0, 2));
  const auto e = optics::depth_distinctness(points(5, {{2, 2}, {2, 3}}));
  CHECK(e.per_band[0] == Approx(1.0).epsilon(1e-15));
}

TEST_CASE("scene depth cue: a one-pixel shift matches the closed form, the same PSF gives 0, a wider blur change more",
          "[optics][cue]") {
  // H' = H exp(-2 pi i f_x) for a shift by one column; |H| = 1 for a point, so
  // r = sum_f S(f) (2 - 2 cos 2 pi f_x) / sum_f S(f), S = 1 / (|f|^2 + f0^2).
  const double f0 = 1.0 / 64;
  const int64_t N = 128;  // the cue's DFT size for P <= 64
  double num = 0, den = 0;
  for (int64_t i = 0; i < N; ++i)
    for (int64_t j = 0; j < N; ++j) {
      const double fy = double(i < N / 2 ? i : i - N) / double(N), fx = double(j < N / 2 ? j : j - N) / double(N);
      const double S = 1.0 / (fx * fx + fy * fy + f0 * f0);
      num += S * (2.0 - 2.0 * std::cos(2.0 * M_PI * fx));
      den += S;
    }
  const auto shift = optics::scene_depth_cue(points(5, {{2, 2}, {2, 3}}), f0);
  CHECK(shift.min_per_slice[0] == Approx(num / den).epsilon(1e-10));
  CHECK(shift.mean_per_slice[0] == Approx(num / den).epsilon(1e-10));

  const auto same = optics::scene_depth_cue(points(5, {{2, 2}, {2, 2}}), f0);
  CHECK(same.min_per_slice[0] == Approx(0.0).margin(1e-15));

  // Blur widths 1 (a point), 3 and 9 px: the change from a point grows with
  // the blur, and a stack's smallest value is its closest pair's.
  const int64_t P = 15;
  auto cue = [&](std::vector<torch::Tensor> slices) { return optics::scene_depth_cue(torch::stack(slices).unsqueeze(0), f0); };
  const double r13 = cue({box(P, 1), box(P, 3)}).min_per_slice[0];
  const double r19 = cue({box(P, 1), box(P, 9)}).min_per_slice[0];
  const double r39 = cue({box(P, 3), box(P, 9)}).min_per_slice[0];
  CHECK(r13 > 0.0);
  CHECK(r19 > r13);
  const auto all = cue({box(P, 1), box(P, 3), box(P, 9)});
  CHECK(all.min_per_slice[0] == Approx(std::min({r13, r19, r39})).epsilon(1e-12));
  CHECK(all.mean_per_slice[0] == Approx((r13 + r19 + r39) / 3).epsilon(1e-12));
}
