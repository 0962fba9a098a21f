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

TEST_CASE("scene depth cue: zero for a shift (only the MTF reaches a scene), the closed form of a two-tap blur, "
          "growing with the change of blur width",
          "[optics][cue]") {
  const double f0 = 1.0 / 64, s2 = 1e-3;
  const int64_t N = 128;  // the cue's DFT size for P <= 64
  // A one-pixel shift: total variation 1, and the same image statistics.
  const auto shift = optics::scene_depth_cue(points(5, {{2, 2}, {2, 3}}), s2, f0);
  CHECK(shift.min_per_slice[0] == Approx(0.0).margin(1e-14));
  CHECK(optics::depth_distinctness(points(5, {{2, 2}, {2, 3}})).per_band[0] == Approx(1.0));

  // A point against a two-tap blur (½, ½) along x: |H|² = 1 and cos²(π f_x);
  // with S = 1/(|f|² + f0²) normalised to mean 1, P = S + σ², P' = S cos² + σ²,
  // D = mean_f ½ (P − P')² / (P P').
  std::vector<double> S(size_t(N * N)), fxs(size_t(N * N));
  double Smean = 0;
  for (int64_t i = 0; i < N; ++i)
    for (int64_t j = 0; j < N; ++j) {
      const double fy = double(i < N / 2 ? i : i - N) / double(N), fx = double(j < N / 2 ? j : j - N) / double(N);
      S[size_t(i * N + j)] = 1.0 / (fx * fx + fy * fy + f0 * f0);
      fxs[size_t(i * N + j)] = fx;
      Smean += S[size_t(i * N + j)] / double(N * N);
    }
  double D = 0;
  for (size_t k = 0; k < S.size(); ++k) {
    const double s = S[k] / Smean, c = std::cos(M_PI * fxs[k]);
    const double Pa = s + s2, Pb = s * c * c + s2;
    D += 0.5 * (Pa - Pb) * (Pa - Pb) / (Pa * Pb) / double(S.size());
  }
  torch::Tensor two = points(5, {{2, 2}, {2, 2}});
  two[0][1][2][2] = 0.5;
  two[0][1][2][3] = 0.5;
  const auto tap = optics::scene_depth_cue(two, s2, f0);
  CHECK(tap.min_per_slice[0] == Approx(D).epsilon(1e-10));
  CHECK(tap.mean_per_slice[0] == Approx(D).epsilon(1e-10));
  CHECK(D > 0.01);

  // More noise hides more of it.
  CHECK(optics::scene_depth_cue(two, 1e-1, f0).min_per_slice[0] < D);

  // Blur widths 1 (a point), 3 and 9 px: the change from a point grows with
  // the blur, and a stack's min and mean are over its pairs.
  const int64_t P = 15;
  auto cue = [&](std::vector<torch::Tensor> slices) {
    return optics::scene_depth_cue(torch::stack(slices).unsqueeze(0), s2, f0);
  };
  const double r13 = cue({box(P, 1), box(P, 3)}).min_per_slice[0];
  const double r19 = cue({box(P, 1), box(P, 9)}).min_per_slice[0];
  const double r39 = cue({box(P, 3), box(P, 9)}).min_per_slice[0];
  CHECK(r13 > 0.0);
  CHECK(r19 > r13);
  const auto all = cue({box(P, 1), box(P, 3), box(P, 9)});
  CHECK(all.min_per_slice[0] == Approx(std::min({r13, r19, r39})).epsilon(1e-12));
  CHECK(all.mean_per_slice[0] == Approx((r13 + r19 + r39) / 3).epsilon(1e-12));
}
