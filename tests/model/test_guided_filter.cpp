// The guided filter (model/guided_filter.h) against its definition evaluated
// window by window with loops, its limits (a constant kept, a huge ε the box
// mean of the box mean, the guide's own edge kept), linearity, a float64
// gradient check and bad input; the fused depth's pieces (model/depth_fusion.h):
// the guide's scale, a noisy two-layer cost read right up to the guide's edge,
// the average and its clamp.
#include <catch2/catch.hpp>

#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "common/error.h"
#include "model/depth_fusion.h"
#include "model/guided_filter.h"

using namespace hsd;

namespace {

const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);

// He et al.'s Eqs. 5, 6 and 8 by loops: a, b per window (cut at the border),
// then each pixel's mean of the coefficients of the windows holding it.
torch::Tensor guided_by_loops(const torch::Tensor& I, const torch::Tensor& p, int64_t r, double eps) {
  const int64_t H = I.size(2), W = I.size(3);
  auto Ia = I.accessor<double, 4>();
  auto pa = p.accessor<double, 4>();
  std::vector<double> a(size_t(H * W)), b(size_t(H * W));
  for (int64_t y = 0; y < H; ++y)
    for (int64_t x = 0; x < W; ++x) {
      double n = 0, sI = 0, sp = 0, sII = 0, sIp = 0;
      for (int64_t v = std::max<int64_t>(0, y - r); v <= std::min(H - 1, y + r); ++v)
        for (int64_t u = std::max<int64_t>(0, x - r); u <= std::min(W - 1, x + r); ++u) {
          const double i = Ia[0][0][v][u], q = pa[0][0][v][u];
          n += 1, sI += i, sp += q, sII += i * i, sIp += i * q;
        }
      const double mI = sI / n, mp = sp / n;
      const double ak = (sIp / n - mI * mp) / (sII / n - mI * mI + eps);
      a[size_t(y * W + x)] = ak, b[size_t(y * W + x)] = mp - ak * mI;
    }
  torch::Tensor q = torch::zeros_like(p);
  auto qa = q.accessor<double, 4>();
  for (int64_t y = 0; y < H; ++y)
    for (int64_t x = 0; x < W; ++x) {
      double n = 0, sa = 0, sb = 0;
      for (int64_t v = std::max<int64_t>(0, y - r); v <= std::min(H - 1, y + r); ++v)
        for (int64_t u = std::max<int64_t>(0, x - r); u <= std::min(W - 1, x + r); ++u)
          n += 1, sa += a[size_t(v * W + u)], sb += b[size_t(v * W + u)];
      qa[0][0][y][x] = sa / n * Ia[0][0][y][x] + sb / n;
    }
  return q;
}

double max_abs(const torch::Tensor& t) { return t.abs().max().item<double>(); }

}  // namespace

TEST_CASE("guided filter: equals its definition window by window, keeps constants and the guide's edges", "[guided_filter]") {
  torch::manual_seed(3);
  const torch::Tensor I = torch::rand({1, 1, 11, 9}, f64), p = torch::rand({1, 1, 11, 9}, f64);
  for (int64_t r : {0, 1, 3}) {
    for (double eps : {1e-3, 0.1}) {
      INFO("r " << r << ", eps " << eps);
      CHECK(max_abs(model::guided_filter(I, p, r, eps) - guided_by_loops(I, p, r, eps)) < 1e-12);
    }
  }
  // The box mean cut at the border: a ramp along x keeps its value inside, and
  // the first column's 5-px box holds columns 0-2 only.
  const torch::Tensor ramp = torch::arange(9, f64).view({1, 1, 1, 9}).expand({1, 1, 11, 9}).contiguous();
  const torch::Tensor bm = model::box_mean(ramp, 2);
  CHECK(max_abs(bm.narrow(3, 2, 5) - ramp.narrow(3, 2, 5)) < 1e-12);
  CHECK(bm[0][0][5][0].item<double>() == Approx(1.0).epsilon(1e-12));
  // A constant input is kept; the filter is linear in the input.
  CHECK(max_abs(model::guided_filter(I, torch::full_like(p, 0.37), 3, 1e-2) - 0.37) < 1e-12);
  const torch::Tensor p2 = torch::rand_like(p);
  CHECK(max_abs(model::guided_filter(I, 2.0 * p - 3.0 * p2, 2, 1e-2) -
                (2.0 * model::guided_filter(I, p, 2, 1e-2) - 3.0 * model::guided_filter(I, p2, 2, 1e-2))) < 1e-12);
  // ε far above the guide's variance: a = 0, and q is the box mean of the box mean.
  CHECK(max_abs(model::guided_filter(I, p, 2, 1e9) - model::box_mean(model::box_mean(p, 2), 2)) < 1e-9);
  // The guide's own step is kept, where the box mean blurs it.
  const torch::Tensor step = (torch::arange(16, f64) >= 8).to(torch::kFloat64).view({1, 1, 1, 16}).expand({1, 1, 12, 16}).contiguous();
  const torch::Tensor kept = model::guided_filter(step, step, 3, 1e-4);
  CHECK(max_abs(kept - step) < 0.01);
  CHECK(max_abs(model::box_mean(step, 3) - step) > 0.4);
  // K channels are filtered alike with one guide.
  const torch::Tensor two = model::guided_filter(I, torch::cat({p, p2}, 1), 2, 1e-2);
  CHECK(max_abs(two.narrow(1, 1, 1) - model::guided_filter(I, p2, 2, 1e-2)) < 1e-15);
}

TEST_CASE("guided filter: float64 gradients in the guide and the input, and bad input refused", "[guided_filter]") {
  torch::manual_seed(4);
  const torch::Tensor I = torch::rand({1, 1, 6, 5}, f64).requires_grad_(true);
  const torch::Tensor p = torch::rand({1, 2, 6, 5}, f64).requires_grad_(true);
  const torch::Tensor w = torch::randn({1, 2, 6, 5}, f64);
  auto f = [&](const torch::Tensor& a, const torch::Tensor& b) {
    return (model::guided_filter(a, b, 1, 0.05) * w).sum();
  };
  const auto g = torch::autograd::grad({f(I, p)}, {I, p});
  const double h = 1e-6;
  for (int which = 0; which < 2; ++which) {
    const torch::Tensor x = which == 0 ? I : p;
    for (int64_t k : std::initializer_list<int64_t>{0, 7, 13, x.numel() - 1}) {
      torch::NoGradGuard ng;
      torch::Tensor up = x.detach().clone(), dn = x.detach().clone();
      up.view(-1)[k] += h, dn.view(-1)[k] -= h;
      const double fd = which == 0 ? (f(up, p) - f(dn, p)).item<double>() / (2 * h)
                                   : (f(I, up) - f(I, dn)).item<double>() / (2 * h);
      INFO("argument " << which << ", element " << k);
      CHECK(g[size_t(which)].view(-1)[k].item<double>() == Approx(fd).epsilon(1e-6).margin(1e-9));
    }
  }
  const torch::Tensor a = torch::rand({1, 1, 6, 5}), b = torch::rand({1, 2, 6, 5});
  CHECK_THROWS_AS(model::guided_filter(torch::rand({1, 2, 6, 5}), b, 1, 0.1), InputError);  // two-channel guide
  CHECK_THROWS_AS(model::guided_filter(a, torch::rand({1, 2, 6, 4}), 1, 0.1), InputError);  // sizes differ
  CHECK_THROWS_AS(model::guided_filter(a, b.to(torch::kFloat64), 1, 0.1), InputError);      // dtypes differ
  CHECK_THROWS_AS(model::guided_filter(a, b, -1, 0.1), InputError);
  CHECK_THROWS_AS(model::guided_filter(a, b, 1, 0.0), InputError);
  CHECK_THROWS_AS(model::box_mean(torch::rand({6, 5}), 1), InputError);
}

TEST_CASE("depth fusion: the guide's scale, a noisy two-layer cost read up to the guide's edge, the average and its clamp",
          "[guided_filter][defocus]") {
  torch::manual_seed(5);
  const torch::Tensor cube = torch::rand({2, 4, 20, 24});
  const torch::Tensor g = model::fusion_guide(cube);
  CHECK(g.sizes() == c10::IntArrayRef{2, 1, 20, 24});
  CHECK(max_abs(g.abs().mean({2, 3}) - 1.0) < 1e-5);
  CHECK(max_abs(model::fusion_guide(7.0 * cube) - g) < 1e-5);
  CHECK(max_abs(model::fusion_guide(torch::zeros({1, 4, 5, 5}))) == 0.0);

  // Two surfaces meeting at column 24: a bright one at layer 0 (0.5 m) and a
  // dark one at layer 1 (2 m); per pixel the costs favour the true layer by 1
  // nat under noise of 1.5 nats, so a pixel alone is read wrong about a third
  // of the time.
  const int64_t H = 32, W = 48;
  const torch::Tensor right = (torch::arange(W) >= 24).view({1, 1, 1, W}).expand({1, 1, H, W});
  const torch::Tensor guide = model::fusion_guide(torch::where(right, torch::full({1, 1, H, W}, 0.2), torch::full({1, 1, H, W}, 1.0)));
  const torch::Tensor truth = torch::where(right, torch::full({1, 1, H, W}, 2.0), torch::full({1, 1, H, W}, 0.5));
  const torch::Tensor favour1 = torch::where(right, torch::full({1, 1, H, W}, -1.0), torch::full({1, 1, H, W}, 1.0));
  const torch::Tensor cost = torch::cat({torch::zeros({1, 1, H, W}), favour1}, 1) + 1.5 * torch::randn({1, 2, H, W});
  const std::vector<double> layers{0.5, 2.0};
  const double alone = (torch::where(cost.argmin(1, true) == 1, 2.0, 0.5) == truth).to(torch::kFloat64).mean().item<double>();
  const torch::Tensor read = model::filtered_reader_depth(cost, guide, layers);
  REQUIRE(read.sizes() == c10::IntArrayRef{1, 1, H, W});
  const double filtered = (read == truth).to(torch::kFloat64).mean().item<double>();
  const torch::Tensor edge = read.narrow(3, 22, 4);  // the two columns each side of the edge
  INFO("right alone " << alone << ", filtered " << filtered);
  CHECK(alone < 0.8);
  CHECK(filtered > 0.99);
  CHECK((edge == truth.narrow(3, 22, 4)).to(torch::kFloat64).mean().item<double>() > 0.97);

  // The average of two constant maps is their mean; out-of-range values are clamped.
  const torch::Tensor net = torch::full({1, 1, H, W}, 1.2), reader = torch::full({1, 1, H, W}, 0.5);
  CHECK(max_abs(model::fuse_depths(net, reader, guide, 0.4, 2.5) - 0.85) < 1e-5);  // float32 sums
  CHECK(max_abs(model::fuse_depths(torch::full({1, 1, H, W}, 9.0), torch::full({1, 1, H, W}, 9.0), guide, 0.4, 2.5) - 2.5) == 0.0);
  CHECK_THROWS_AS(model::fuse_depths(net, reader.narrow(3, 0, 5), guide, 0.4, 2.5), InputError);
  CHECK_THROWS_AS(model::fuse_depths(net, reader, guide, 2.0, 1.0), InputError);
}
