// Gradients of the PSF stack with respect to the DOE height: autograd against
// central finite differences in float64, on a tiny grid.
#include <catch2/catch.hpp>
#include <cmath>

#include "helpers.h"
#include "optics/doe.h"

using namespace hsd;

TEST_CASE("PSF gradient w.r.t. the height map matches finite differences in float64", "[psf][gradient]") {
  const int64_t N = 12, P = 5;
  auto spec = test::make_spec({480e-9, 620e-9}, {0.4, 2.0}, N, 10e-6, 0.11e-3, P, 10e-6, 0.02, 3);
  const optics::PsfSimulator sim(spec);
  torch::manual_seed(3);
  const torch::Tensor h0 = optics::random_height(N, 1.2e-6, 11);
  const torch::Tensor w = torch::randn({2, 2, P, P}, torch::kFloat64);
  auto loss = [&](const torch::Tensor& h) {
    const auto out = sim.compute(h);
    // weighted PSF plus a term through energy-normalisation-free intensity
    return (out.psf * w).sum() + (out.psf.pow(2) * w.abs()).sum();
  };
  torch::Tensor h = h0.clone().set_requires_grad(true);
  const torch::Tensor L = loss(h);
  L.backward();
  const torch::Tensor g = h.grad();
  REQUIRE(torch::isfinite(g).all().item<bool>());
  REQUIRE(g.abs().max().item<double>() > 0.0);

  const double eps = 1e-11;  // metres (phase change ~1e-4 rad)
  int checked = 0;
  for (int64_t idx : {int64_t(5 * N + 5), int64_t(6 * N + 3), int64_t(4 * N + 7), int64_t(7 * N + 6), int64_t(2 * N + 5)}) {
    const int64_t i = idx / N, j = idx % N;
    torch::Tensor hp = h0.clone(), hm = h0.clone();
    hp[i][j] += eps;
    hm[i][j] -= eps;
    const double fd = (loss(hp).item<double>() - loss(hm).item<double>()) / (2.0 * eps);
    const double ad = g[i][j].item<double>();
    INFO("sample (" << i << ", " << j << "): autograd " << ad << ", finite difference " << fd);
    CHECK(std::fabs(ad - fd) <= 1e-6 * std::max(1.0, std::fabs(fd)) + 1e-6 * g.abs().max().item<double>());
    ++checked;
  }
  CHECK(checked == 5);
}

TEST_CASE("gradients flow through the DOE constraints: wrap and straight-through quantization", "[doe][gradient]") {
  const int64_t N = 12;
  auto spec = test::make_spec({550e-9}, {1.0}, N, 10e-6, 0.11e-3, 5, 10e-6, 0.02, 2);
  const optics::PsfSimulator sim(spec);
  const torch::Tensor h0 = optics::random_height(N, 1.0e-6, 5);
  optics::Doe doe(h0, 1.1e-6, 8, 10e-6);
  const torch::Tensor h = doe.height();
  // forward: 8 levels, multiples of max/8
  const torch::Tensor levels = (h.detach() / (1.1e-6 / 8)).round();
  CHECK(((h.detach() / (1.1e-6 / 8)) - levels).abs().max().item<double>() < 1e-9);
  CHECK(levels.max().item<double>() <= 7.0);
  sim.compute(h).psf.select(2, 2).select(2, 2).sum().backward();
  CHECK(doe.parameter().grad().defined());
  CHECK(doe.parameter().grad().abs().sum().item<double>() > 0.0);
}

TEST_CASE("float32 and float64 gradients agree", "[psf][gradient]") {
  const int64_t N = 32, P = 9;
  const torch::Tensor h0 = optics::random_height(N, 1.2e-6, 21);
  torch::Tensor grads[2];
  int k = 0;
  for (auto dt : {torch::kFloat64, torch::kFloat32}) {
    auto spec = test::make_spec({450e-9, 650e-9}, {0.5, 1.5}, N, 8e-6, 0.25e-3, P, 8e-6, 0.03, 3, dt);
    torch::Tensor h = h0.clone().set_requires_grad(true);
    const auto out = optics::PsfSimulator(spec).compute(h);
    (out.psf.select(2, P / 2).select(2, P / 2).sum()).backward();
    grads[k++] = h.grad().to(torch::kFloat64);
  }
  const double rel = ((grads[0] - grads[1]).norm() / grads[0].norm()).item<double>();
  INFO("relative difference float32 vs float64 gradient: " << rel);
  CHECK(rel < 1e-4);
}

// The simulator is a temporary here: the recomputation must not depend on it
// outliving the forward pass.
TEST_CASE("recomputing bands in the backward pass gives the same gradient", "[psf][gradient]") {
  const int64_t N = 24, P = 7;
  const torch::Tensor h0 = optics::random_height(N, 1.2e-6, 4);
  torch::Tensor grads[2];
  for (int k = 0; k < 2; ++k) {
    auto spec = test::make_spec({450e-9, 650e-9}, {0.5, 1.5}, N, 8e-6, 0.18e-3, P, 8e-6, 0.03, 3);
    spec.recompute_in_backward = (k == 1);
    torch::Tensor h = h0.clone().set_requires_grad(true);
    const auto out = optics::PsfSimulator(spec).compute(h);
    (out.psf.pow(2).sum() + out.psf.select(2, 1).sum()).backward();
    grads[k] = h.grad();
  }
  CHECK(grads[0].abs().max().item<double>() > 0.0);
  CHECK(torch::allclose(grads[0], grads[1], 1e-10, 1e-14));
}

TEST_CASE("the PSF gradient through the joint depth basis matches finite differences in float64", "[psf][gradient]") {
  const int64_t N = 12, P = 5;
  auto spec = test::make_spec({480e-9, 620e-9}, {0.4, 0.8, 2.0}, N, 10e-6, 0.11e-3, P, 10e-6, 0.02, 3);
  spec.mft_rank_tol = 1e-4;
  spec.depth_basis = true;
  const optics::PsfSimulator sim(spec);
  REQUIRE(sim.depth_basis_ranks()[0] > 0);
  const torch::Tensor h0 = optics::random_height(N, 1.2e-6, 5);
  torch::manual_seed(4);
  const torch::Tensor w = torch::randn({2, 3, P, P}, torch::kFloat64);
  auto loss = [&](const torch::Tensor& h) { return (sim.compute(h).psf * w).sum(); };
  torch::Tensor h = h0.clone().set_requires_grad(true);
  loss(h).backward();
  const torch::Tensor g = h.grad();
  REQUIRE(g.abs().max().item<double>() > 0.0);
  const double eps = 1e-11;
  for (int64_t idx : {int64_t(5 * N + 5), int64_t(6 * N + 3), int64_t(4 * N + 7), int64_t(7 * N + 6)}) {
    const int64_t i = idx / N, j = idx % N;
    torch::Tensor hp = h0.clone(), hm = h0.clone();
    hp[i][j] += eps;
    hm[i][j] -= eps;
    const double fd = (loss(hp).item<double>() - loss(hm).item<double>()) / (2.0 * eps);
    INFO("sample (" << i << ", " << j << "): autograd " << g[i][j].item<double>() << ", finite difference " << fd);
    CHECK(std::fabs(g[i][j].item<double>() - fd) <= 1e-6 * std::max(1.0, std::fabs(fd)) + 1e-6 * g.abs().max().item<double>());
  }
}
