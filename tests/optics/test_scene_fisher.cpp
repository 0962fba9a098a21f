// The scene Fisher bound (optics/scene_fisher.h): the Whittle information
// against a closed form, the derivative of the image spectrum against finite
// differences, a float64 gradient check of the aggregate in the height map,
// blindness to a shift, and a design that lowers its own bound.
#include <catch2/catch.hpp>
#include <cmath>

#include "helpers.h"
#include "optics/doe.h"
#include "optics/fisher.h"
#include "optics/fisher_design.h"
#include "optics/scene_fisher.h"

using namespace hsd;

namespace {
// 48 DOE samples of 10 µm (0.44 mm aperture), 11-px window of 10 µm, s = 20 mm (test_fisher's geometry).
optics::FisherGeometry small_geometry() {
  const auto spec = test::make_spec({500e-9, 600e-9}, {0.3, 1.0}, 48, 10e-6, 0.44e-3, 11, 10e-6, 0.02, 2);
  return optics::make_fisher_geometry(spec, 11, 2);
}
optics::FisherSettings small_settings() {
  optics::FisherSettings s;
  s.wavelengths_nm = {500, 600};
  s.depths_m = {0.3, 0.5, 1.0};
  s.inv_depth_spacing = (1.0 / 0.3 - 1.0) / 2;
  s.nuisance = {NuisanceParam::N};
  return s;
}
optics::SceneFisherSettings small_scene() {
  optics::SceneFisherSettings sc;
  sc.camera_response = torch::tensor({{0.2, 1.0}, {1.0, 0.3}}, torch::kFloat64);  // two channels over the two bands
  sc.noise_variance = 1e-3;
  sc.patch_px = 32;
  return sc;
}
torch::Tensor fresnel_h() { return optics::fresnel_height(48, 10e-6, 550e-9, 1.46, 0.5, 0.02).to(torch::kFloat64); }
}  // namespace

TEST_CASE("scene fisher: the Whittle information of a power model matches the closed form", "[fisher][scene]") {
  // P(f) = a s(f) + σ² with a = 1: I_aa = ½ Σ (s / P)², and a parameter that
  // scales P itself, P = b q, has I_bb = ½ (number of frequencies) at b = 1.
  torch::manual_seed(1);
  const torch::Tensor s = torch::rand({2, 4, 4}, torch::kFloat64) + 0.1;
  const double s2 = 0.05;
  const torch::Tensor P = s + s2;
  const torch::Tensor I = optics::scene_fisher_from_power(P, {s, P});
  CHECK(I[0][0].item<double>() == Approx((0.5 * (s / P).square()).sum().item<double>()).epsilon(1e-12));
  CHECK(I[1][1].item<double>() == Approx(0.5 * 32).epsilon(1e-12));
  CHECK(I[0][1].item<double>() == Approx((0.5 * s / P).sum().item<double>()).epsilon(1e-12));
  CHECK(I[0][1].item<double>() == Approx(I[1][0].item<double>()).epsilon(1e-15));
}

TEST_CASE("scene fisher: the channel PSFs' spectrum has autograd derivatives equal to finite differences, and a "
          "shifted PSF carries the same information",
          "[fisher][scene]") {
  torch::manual_seed(3);
  const auto g = small_geometry();
  const auto s = small_settings();
  const auto sc = small_scene();
  const auto material = optics::Material::constant(1.46);
  const torch::Tensor h = fresnel_h();
  auto mtf2 = [&](const torch::Tensor& D) {
    const torch::Tensor psf = optics::camera_channel_psfs(g, material, h, D, s.wavelengths_nm, sc.camera_response);
    const torch::Tensor H = torch::fft::fft2(torch::constant_pad_nd(psf, {0, 128 - 11, 0, 128 - 11}));
    return torch::real(H).square() + torch::imag(H).square();
  };
  // The channel PSFs are the response-weighted means of the band PSFs.
  const torch::Tensor D0 = torch::tensor(2.6, torch::kFloat64);
  const torch::Tensor p = optics::camera_channel_psfs(g, material, h, D0, s.wavelengths_nm, sc.camera_response);
  const torch::Tensor b0 = optics::point_psf(g, h, D0, torch::tensor(500.0, torch::kFloat64), 1.46, 0.0);
  const torch::Tensor b1 = optics::point_psf(g, h, D0, torch::tensor(600.0, torch::kFloat64), 1.46, 0.0);
  CHECK((p[0] - (0.2 * b0 + 1.0 * b1) / 1.2).abs().max().item<double>() < 1e-15);
  // dP/dD by autograd against central differences.
  const torch::Tensor D = torch::tensor(2.6, torch::kFloat64).requires_grad_(true);
  const auto J = optics::jacobian_by_autograd(mtf2(D), {D}, false);
  const double e = 1e-4;
  const torch::Tensor fd = (mtf2(torch::tensor(2.6 + e, torch::kFloat64)) - mtf2(torch::tensor(2.6 - e, torch::kFloat64))) / (2 * e);
  REQUIRE(J[0].abs().max().item<double>() > 0);
  CHECK((J[0] - fd).abs().max().item<double>() < 1e-6 * J[0].abs().max().item<double>());
  // A whole-pixel shift of a PSF (rolled inside a zero border) leaves |H| and so the information unchanged.
  const torch::Tensor q = torch::zeros({1, 1, 11, 11}, torch::kFloat64);
  q[0][0].slice(0, 2, 7).slice(1, 2, 7).copy_(torch::rand({5, 5}, torch::kFloat64));
  const torch::Tensor q_shift = torch::roll(q, {3, 2}, {2, 3});
  auto m = [](const torch::Tensor& x) {
    const torch::Tensor H = torch::fft::fft2(torch::constant_pad_nd(x, {0, 117, 0, 117}));
    return torch::real(H).square() + torch::imag(H).square();
  };
  CHECK((m(q) - m(q_shift)).abs().max().item<double>() < 1e-12 * m(q).max().item<double>());
}

TEST_CASE("scene fisher: the bound per depth is sqrt of the inverse information, its gradient in the height map "
          "matches finite differences in float64, and the design lowers it",
          "[fisher][scene]") {
  torch::manual_seed(2);
  const auto g = small_geometry();
  auto s = small_settings();
  const auto sc = small_scene();
  const auto material = optics::Material::constant(1.46);
  const torch::Tensor h = fresnel_h();
  // With the contrast known the bound is 1 / sqrt(I_DD) of the patch, by hand from finite differences.
  optics::FisherSettings known = s;
  known.nuisance.clear();
  const optics::CrlbReport r = optics::scene_crlb_report(g, material, h, known, sc);
  REQUIRE(r.crlb_inv_depth.sizes() == torch::IntArrayRef({1, 3}));
  torch::Tensor S;
  {
    const torch::Tensor f = torch::fft::fftfreq(128, torch::kFloat64);
    S = 1.0 / (f.view({-1, 1}).square() + f.view({1, -1}).square() + 1.0 / 4096);
    S = S / S.mean();
  }
  auto power = [&](double Dv) {
    const torch::Tensor psf = optics::camera_channel_psfs(g, material, h, torch::tensor(Dv, torch::kFloat64),
                                                          s.wavelengths_nm, sc.camera_response);
    const torch::Tensor H = torch::fft::fft2(torch::constant_pad_nd(psf, {0, 117, 0, 117}));
    return S * (torch::real(H).square() + torch::imag(H).square()) + sc.noise_variance;
  };
  for (int64_t z = 0; z < 3; ++z) {
    const double Dv = 1.0 / s.depths_m[size_t(z)], e = 1e-5;
    const torch::Tensor dP = (power(Dv + e) - power(Dv - e)) / (2 * e);
    const double I = (0.5 * (dP / power(Dv)).square()).sum().item<double>() * (32.0 * 32.0) / (128.0 * 128.0);
    CHECK(r.crlb_inv_depth[0][z].item<double>() == Approx(1.0 / std::sqrt(I)).epsilon(1e-5));
  }
  // Contrast unknown: never a tighter bound.
  const optics::CrlbReport rn = optics::scene_crlb_report(g, material, h, s, sc);
  CHECK((rn.crlb_inv_depth - r.crlb_inv_depth).min().item<double>() > -1e-12);

  // Gradient of the aggregate along a random height direction against central differences.
  s.aggregate = CrlbAggregate::mean;
  const torch::Tensor dir = torch::randn({48, 48}, torch::kFloat64) * 20e-9;
  const torch::Tensor hv = h.clone().requires_grad_(true);
  const optics::CrlbReport rg = optics::scene_crlb_report(g, material, hv, s, sc);
  rg.aggregate.backward();
  const double analytic = (hv.grad() * dir).sum().item<double>();
  const double ep = 1e-3;
  const double fd = (optics::scene_crlb_report(g, material, h + ep * dir, s, sc).aggregate.item<double>() -
                     optics::scene_crlb_report(g, material, h - ep * dir, s, sc).aggregate.item<double>()) /
                    (2 * ep);
  INFO("directional derivative: autograd " << analytic << ", finite differences " << fd);
  REQUIRE(std::fabs(fd) > 0);
  CHECK(analytic == Approx(fd).epsilon(1e-4));

  // The design with this bound as its objective ends below its Fresnel start.
  FisherConfig cfg;
  cfg.steps = 8, cfg.zernike_modes = 10, cfg.lr = 0.05;
  const torch::Tensor start = optics::fresnel_lens_height(48, 10e-6, 550e-9, 1.46, 0.5, 0.02);
  const optics::FisherDesign d = optics::design_fisher_doe(
      g, [&](const torch::Tensor& x) { return optics::scene_crlb_report(g, material, x, s, sc); }, start,
      550e-9 / 0.46, cfg);
  INFO("scene aggregate: start " << d.start_aggregate << ", end " << d.final_aggregate);
  CHECK(d.final_aggregate < 0.9 * d.start_aggregate);
  CHECK(std::isfinite(d.final_aggregate));
}
