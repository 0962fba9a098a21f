// Sensor image formation J_c = Σ_z M_z ⊙ Σ_λ Ω_c,λ (I_λ ⊗ P_λ,z): impulse
// response, fast path vs the straightforward one (with and without leave-out),
// uniform scenes without border darkening, bad depth maps, and the gradient
// from the image back to the DOE height map.
#include <catch2/catch.hpp>
#include <cmath>

#include "common/error.h"
#include "helpers.h"
#include "optics/doe.h"
#include "optics/sensor_image.h"

using namespace hsd;

namespace {
torch::Tensor random_psf(int64_t L, int64_t Z, int64_t P, uint64_t seed) {
  auto gen = at::detail::createCPUGenerator(seed);
  torch::Tensor p = torch::rand({L, Z, P, P}, gen, torch::kFloat64);
  return p / p.sum({2, 3}, true);
}
}  // namespace

TEST_CASE("sensor: an impulse at one layer's depth reproduces the PSFs weighted by the camera response", "[sensor]") {
  const int64_t L = 4, Z = 3, P = 7, H = 21, W = 25;
  const std::vector<double> depths{0.5, 1.0, 2.0};
  const torch::Tensor psf = random_psf(L, Z, P, 1);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  for (int64_t z = 0; z < Z; ++z) {
    torch::Tensor I = torch::zeros({1, L, H, W}, torch::kFloat64);
    I.select(2, 10).select(2, 12).fill_(1.0);  // all bands, pixel (10, 12)
    const torch::Tensor depth = torch::full({1, 1, H, W}, depths[size_t(z)], torch::kFloat64);
    const torch::Tensor masks = optics::layer_masks(depth, depths, 0.0);
    const torch::Tensor J = optics::render_sensor_image(I, masks, psf, omega);
    const torch::Tensor expected = torch::einsum("cl,lhw->chw", {omega, psf.select(1, z)});  // [3, P, P]
    const torch::Tensor got = J[0].narrow(1, 10 - P / 2, P).narrow(2, 12 - P / 2, P);
    CHECK((got - expected).abs().max().item<double>() < 1e-12);
    CHECK(J.sum().item<double>() == Approx(expected.sum().item<double>()).epsilon(1e-12));
  }
}

TEST_CASE("sensor: the fast path, leaving out unseen bands and empty layers, equals the straightforward one over all of them", "[sensor]") {
  const int64_t L = 5, Z = 4, P = 9, H = 32, W = 28, B = 2;
  const std::vector<double> depths{0.4, 0.6, 1.0, 2.0};
  torch::manual_seed(0);
  const torch::Tensor psf = random_psf(L, Z, P, 2).to(torch::kFloat32);
  torch::Tensor omega = torch::rand({3, L});
  omega.select(1, 2).zero_();  // a band the camera does not see: left out
  const torch::Tensor I = torch::rand({B, L, H, W});
  // Depth: two of the four layers occupied.
  torch::Tensor depth = torch::full({B, 1, H, W}, 0.4);
  depth.narrow(3, W / 2, W / 2).fill_(1.0);
  REQUIRE(optics::occupied_layers(depth, depths) == std::vector<int64_t>{0, 2});
  const torch::Tensor masks = optics::layer_masks(depth, depths, 1.5);
  const torch::Tensor direct = optics::render_sensor_image_direct(I, masks, psf, omega);
  const torch::Tensor fast = optics::render_sensor_image(I, masks, psf, omega);
  const double scale = direct.abs().max().item<double>();
  CHECK((fast - direct).abs().max().item<double>() < 1e-5 * scale);
  // random depths over all layers
  const torch::Tensor depth2 = 0.35 + 2.0 * torch::rand({B, 1, H, W});
  const torch::Tensor masks2 = optics::layer_masks(depth2, depths, 0.8);
  const torch::Tensor d2 = optics::render_sensor_image_direct(I, masks2, psf, omega);
  CHECK((optics::render_sensor_image(I, masks2, psf, omega) - d2).abs().max().item<double>() <
        1e-5 * d2.abs().max().item<double>());
}

TEST_CASE("sensor: a uniform scene stays uniform up to the borders", "[sensor]") {
  const int64_t L = 3, Z = 2, P = 11, H = 24, W = 24;
  const std::vector<double> depths{0.5, 1.5};
  const torch::Tensor psf = random_psf(L, Z, P, 3);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const torch::Tensor I = torch::full({1, L, H, W}, 0.7, torch::kFloat64);
  torch::Tensor depth = torch::full({1, 1, H, W}, 0.5, torch::kFloat64);
  depth.narrow(2, 0, H / 2).fill_(1.5);
  const torch::Tensor J = optics::render_sensor_image(I, optics::layer_masks(depth, depths, 2.0), psf, omega);
  const torch::Tensor expected = 0.7 * omega.sum(1);  // PSFs sum to 1, masks to 1
  for (int64_t c = 0; c < 3; ++c)
    CHECK((J[0][c] - expected[c]).abs().max().item<double>() < 1e-12);
}

TEST_CASE("sensor: bad depth maps are refused with a message", "[sensor]") {
  const std::vector<double> depths{0.5, 1.5};
  torch::Tensor d = torch::full({1, 1, 4, 4}, 1.0);
  d[0][0][1][1] = std::nan("");
  CHECK_THROWS_WITH(optics::layer_masks(d, depths, 0.0), Catch::Contains("NaN"));
  d[0][0][1][1] = 0.0;
  CHECK_THROWS_WITH(optics::layer_masks(d, depths, 0.0), Catch::Contains("negative"));
  d[0][0][1][1] = -2.0;
  CHECK_THROWS_AS(optics::layer_masks(d, depths, 0.0), InputError);
  d[0][0][1][1] = std::numeric_limits<float>::infinity();
  CHECK_THROWS_AS(optics::layer_masks(d, depths, 0.0), InputError);
}

TEST_CASE("sensor: gradient from the image reaches the height map and matches finite differences", "[sensor][gradient]") {
  const int64_t N = 12, P = 5, H = 10, W = 10;
  const std::vector<double> depths{0.4, 2.0};
  auto spec = test::make_spec({480e-9, 620e-9}, depths, N, 10e-6, 0.11e-3, P, 10e-6, 0.02, 2);
  const optics::PsfSimulator sim(spec);
  const torch::Tensor h0 = optics::random_height(N, 1.2e-6, 9);
  torch::manual_seed(4);
  const torch::Tensor I = torch::rand({1, 2, H, W}, torch::kFloat64);
  torch::Tensor depth = torch::full({1, 1, H, W}, 0.4, torch::kFloat64);
  depth.narrow(3, 0, 4).fill_(2.0);
  const torch::Tensor masks = optics::layer_masks(depth, depths, 1.0);
  const torch::Tensor omega = torch::rand({3, 2}, torch::kFloat64);
  const torch::Tensor w = torch::randn({1, 3, H, W}, torch::kFloat64);
  auto loss = [&](const torch::Tensor& h) {
    return (optics::render_sensor_image(I, masks, sim.compute(h).psf, omega) * w).sum();
  };
  torch::Tensor h = h0.clone().set_requires_grad(true);
  loss(h).backward();
  const torch::Tensor g = h.grad();
  REQUIRE(g.abs().max().item<double>() > 0.0);
  const double eps = 1e-11;
  for (int64_t idx : {int64_t(5 * N + 5), int64_t(6 * N + 4), int64_t(3 * N + 6)}) {
    torch::Tensor hp = h0.clone(), hm = h0.clone();
    hp.view(-1)[idx] += eps;
    hm.view(-1)[idx] -= eps;
    const double fd = (loss(hp).item<double>() - loss(hm).item<double>()) / (2 * eps);
    const double ad = g.view(-1)[idx].item<double>();
    INFO("autograd " << ad << " finite difference " << fd);
    CHECK(std::fabs(ad - fd) <= 1e-6 * std::max(1.0, std::fabs(fd)) + 1e-6 * g.abs().max().item<double>());
  }
}

TEST_CASE("sensor: the PSF gradient of the fast node equals that of generic autograd ops", "[sensor][gradient]") {
  // render_sensor_image differentiates the PSFs with its own backward pass
  // (LayerSpectrum) unless the radiance needs a gradient, when it composes
  // generic ops; both must give the same dL/dPSF, here in float64 with B = 2.
  const int64_t L = 4, Z = 3, P = 7, H = 20, W = 18, B = 2;
  const std::vector<double> depths{0.5, 0.9, 2.0};
  const torch::Tensor psf0 = random_psf(L, Z, P, 11);
  torch::manual_seed(12);
  const torch::Tensor I = torch::rand({B, L, H, W}, torch::kFloat64);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const torch::Tensor masks = optics::layer_masks(0.45 + 2.0 * torch::rand({B, 1, H, W}, torch::kFloat64), depths, 1.0);
  const torch::Tensor w = torch::randn({B, 3, H, W}, torch::kFloat64);
  auto grads = [&](bool radiance_grad) {
    torch::Tensor p = psf0.clone().set_requires_grad(true);
    torch::Tensor i = I.clone().set_requires_grad(radiance_grad);
    (optics::render_sensor_image(i, masks, p, omega) * w).sum().backward();
    return p.grad();
  };
  const torch::Tensor fast = grads(false), generic = grads(true);
  REQUIRE(generic.abs().max().item<double>() > 0.0);
  CHECK((fast - generic).abs().max().item<double>() < 1e-10 * generic.abs().max().item<double>());
}

TEST_CASE("sensor: occlusion compositing keeps a uniform scene uniform and matches the linear model for one layer",
          "[sensor][occlusion]") {
  const int64_t L = 3, Z = 2, P = 9, H = 24, W = 24;
  const std::vector<double> depths{0.5, 1.5};
  const torch::Tensor psf = random_psf(L, Z, P, 5);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  torch::Tensor depth = torch::full({1, 1, H, W}, 0.5, torch::kFloat64);
  depth.narrow(3, 0, W / 2).fill_(1.5);
  const torch::Tensor alphas = optics::layer_masks(depth, depths, 0.0);
  const torch::Tensor I = torch::full({1, L, H, W}, 0.3, torch::kFloat64);
  const torch::Tensor J = optics::render_sensor_image_occlusion(I, alphas, psf, omega, depths);
  const torch::Tensor expected = 0.3 * omega.sum(1);
  for (int64_t c = 0; c < 3; ++c) CHECK((J[0][c] - expected[c]).abs().max().item<double>() < 1e-9);
  // One layer everywhere: identical to the paper's linear model.
  const torch::Tensor Ir = torch::rand({1, L, H, W}, torch::kFloat64);
  const torch::Tensor one = optics::layer_masks(torch::full({1, 1, H, W}, 1.5, torch::kFloat64), depths, 0.0);
  const torch::Tensor lin = optics::render_sensor_image(Ir, one, psf, omega);
  const torch::Tensor occ = optics::render_sensor_image_occlusion(Ir, one, psf, omega, depths);
  CHECK((lin - occ).abs().max().item<double>() < 1e-9);
}

TEST_CASE("sensor: an opaque near layer hides what lies behind it", "[sensor][occlusion]") {
  const int64_t L = 2, P = 7, H = 40, W = 40;
  const std::vector<double> depths{0.5, 2.0};
  const torch::Tensor psf = random_psf(L, 2, P, 6);
  const torch::Tensor omega = torch::ones({3, L}, torch::kFloat64);
  // Far layer bright everywhere except a near black square in the middle.
  torch::Tensor depth = torch::full({1, 1, H, W}, 2.0, torch::kFloat64);
  depth.narrow(2, 10, 20).narrow(3, 10, 20).fill_(0.5);
  torch::Tensor I = torch::ones({1, L, H, W}, torch::kFloat64);
  I.narrow(2, 10, 20).narrow(3, 10, 20).zero_();
  const torch::Tensor alphas = optics::layer_masks(depth, depths, 0.0);
  const torch::Tensor J = optics::render_sensor_image_occlusion(I, alphas, psf, omega, depths);
  CHECK(J[0][1][20][20].item<double>() < 1e-9);               // deep inside the near square: black
  CHECK(J[0][1][2][2].item<double>() == Approx(2.0).epsilon(1e-9));  // far away from it: 2 bands of 1
}

TEST_CASE("sensor: a crop rendered with a margin of the PSF's reach equals the whole scene's image at its centre",
          "[sensor][train]") {
  // What training patches rely on (data.render_margin_px): the light that
  // neighbouring scene content blurs into a patch is there, not an
  // edge-replicated stand-in. Margin r + 3σ of the soft layer masks suffices.
  const int64_t L = 4, Z = 3, P = 9, H = 48, W = 52, S = 16, r = P / 2;
  const double sigma = 1.0;
  const int64_t m = r + 3;
  const std::vector<double> depths{0.5, 1.0, 2.0};
  torch::manual_seed(4);
  const torch::Tensor psf = random_psf(L, Z, P, 3);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const torch::Tensor I = torch::rand({1, L, H, W}, torch::kFloat64);
  const torch::Tensor depth = 0.45 + 1.8 * torch::rand({1, 1, H, W}, torch::kFloat64);
  const torch::Tensor whole = optics::render_sensor_image(I, optics::layer_masks(depth, depths, sigma), psf, omega);
  const int64_t y0 = 17, x0 = 20;  // patch corner; the crop spans [y0 - m, y0 + S + m)
  auto crop = [&](const torch::Tensor& t, int64_t k) { return t.narrow(2, y0 - k, S + 2 * k).narrow(3, x0 - k, S + 2 * k); };
  const torch::Tensor with_margin =
      optics::render_sensor_image(crop(I, m), optics::layer_masks(crop(depth, m), depths, sigma), psf, omega);
  const torch::Tensor without =
      optics::render_sensor_image(crop(I, 0), optics::layer_masks(crop(depth, 0), depths, sigma), psf, omega);
  const torch::Tensor truth = crop(whole, 0);
  const double scale = truth.abs().max().item<double>();
  CHECK((with_margin.narrow(2, m, S).narrow(3, m, S) - truth).abs().max().item<double>() < 1e-10 * scale);
  // Without the margin the patch's border pixels are wrong by a visible amount.
  CHECK((without - truth).abs().max().item<double>() > 1e-2 * scale);
}
