// The simulator's discretisation knobs (pupil oversampling, cell integration,
// spectral samples per band) and leaving out what a scene does not need:
// convergence, consistency with independent computations, float64 gradients,
// and equality of every leave-out rule with the full computation.
#include <catch2/catch.hpp>
#include <cmath>

#include "common/error.h"
#include "helpers.h"
#include "optics/doe.h"
#include "optics/pixel_quadrature.h"
#include "optics/sampling_check.h"
#include "optics/sensor.h"
#include "optics/sensor_image.h"
#include "optics/spectrum.h"

using namespace hsd;

namespace {
double rel_l1_max(const torch::Tensor& a, const torch::Tensor& ref) {
  return ((a.to(torch::kFloat64) - ref).abs().sum({2, 3}) / ref.abs().sum({2, 3})).max().item<double>();
}
}  // namespace

TEST_CASE("pupil oversampling converges and sinc cell integration beats the midpoint rule", "[psf][discretisation]") {
  // A stiff case: a near source and a short wavelength make large phase steps per DOE cell.
  const int64_t N = 48;
  const double pitch = 10e-6;
  auto spec = test::make_spec({420e-9}, {0.05, 0.2}, N, pitch, 0.45e-3, 15, 4e-6, 0.03, 3);
  const torch::Tensor h = optics::fresnel_height(N, pitch, 550e-9, 1.5, 0.1, 0.03);
  torch::NoGradGuard ng;
  auto run = [&](int64_t k, CellIntegration rule) {
    auto s = spec;
    s.pupil_oversampling = k;
    s.pupil_cell_integration = rule;
    return optics::PsfSimulator(s).compute(h).psf;
  };
  const torch::Tensor ref = run(8, CellIntegration::sinc_cross);
  const double mid1 = rel_l1_max(run(1, CellIntegration::midpoint), ref), mid2 = rel_l1_max(run(2, CellIntegration::midpoint), ref);
  const double sinc1 = rel_l1_max(run(1, CellIntegration::sinc), ref), sinc2 = rel_l1_max(run(2, CellIntegration::sinc), ref);
  const double cross1 = rel_l1_max(run(1, CellIntegration::sinc_cross), ref), cross2 = rel_l1_max(run(2, CellIntegration::sinc_cross), ref);
  INFO("midpoint x1 " << mid1 << ", x2 " << mid2 << "; sinc x1 " << sinc1 << ", x2 " << sinc2 << "; sinc_cross x1 "
                      << cross1 << ", x2 " << cross2);
  CHECK(mid2 < 0.5 * mid1);    // second-order convergence in the cell size
  CHECK(sinc2 < 0.5 * sinc1);
  CHECK(cross2 < 0.5 * cross1);
  CHECK(sinc1 < mid1);         // integrating the linear phase across the cell helps at equal cost
  CHECK(sinc2 < mid2);
  CHECK(cross1 < 0.8 * sinc1);  // and its cross term removes part of what remains (3.3x at the paper geometry)
  // The exact MFT takes the same two kernel terms.
  auto exact = spec;
  exact.mft_rank_tol = 0.0;
  const torch::Tensor a = optics::PsfSimulator(exact).compute(h).psf, b = optics::PsfSimulator(spec).compute(h).psf;
  CHECK(rel_l1_max(b, a) < 1e-5);
  // The reference does not favour the rule it was made with: the midpoint rule
  // at twice its oversampling lands on it, far below the errors compared above.
  const double mid16 = rel_l1_max(run(16, CellIntegration::midpoint), ref);
  INFO("midpoint x16 vs the sinc_cross x8 reference: " << mid16);
  CHECK(mid16 < 0.25 * cross2);
  CHECK(run(3, CellIntegration::sinc).sizes() == ref.sizes());  // the height map stays [N, N] at any k
  // The sampling check uses the sub-sample pitch.
  auto s1 = spec;
  const auto r1 = optics::check_sampling(s1, torch::Tensor(), 0.0);
  s1.pupil_oversampling = 4;
  const auto r4 = optics::check_sampling(s1, torch::Tensor(), 0.0);
  CHECK(r4.max_phase_step_rad.max().item<double>() < 0.3 * r1.max_phase_step_rad.max().item<double>());
}

TEST_CASE("spectral samples: a band's PSF is the Gauss-Legendre mean over the band", "[psf][discretisation]") {
  const int64_t N = 32;
  const double pitch = 8e-6, width = 30e-9;
  auto spec = test::make_spec({500e-9, 600e-9}, {0.3, 1.0}, N, pitch, 0.25e-3, 11, 5e-6, 0.03, 2);
  spec.band_width_m = width;
  spec.spectral_samples = 3;
  const std::vector<double> lam = spec.spectral_wavelengths_m(), w = spec.spectral_weights();
  REQUIRE(lam.size() == 6);
  CHECK(lam[1] == Approx(500e-9).epsilon(1e-12));  // middle node at the centre
  CHECK(lam[2] - lam[0] == Approx(width * std::sqrt(0.6)).epsilon(1e-9));  // 3-node Gauss nodes ±sqrt(3/5)/2
  CHECK(w[0] + w[1] + w[2] == Approx(1.0));
  for (double l : lam) spec.spectral_refractive_index.push_back(1.45 + 1e4 * 1e-9 / l);  // some dispersion
  const torch::Tensor h = optics::fresnel_height(N, pitch, 550e-9, 1.46, 0.5, 0.03);
  torch::NoGradGuard ng;
  const auto band = optics::PsfSimulator(spec).compute(h);
  // Independently: one single-wavelength simulator per node, weighted by hand.
  torch::Tensor manual = torch::zeros_like(band.psf);
  for (size_t j = 0; j < lam.size(); ++j) {
    auto one = test::make_spec({lam[j]}, spec.depths_m, N, pitch, 0.25e-3, 11, 5e-6, 0.03, 2, torch::kFloat64,
                               spec.spectral_refractive_index[j]);
    manual[int64_t(j / 3)] += w[j] * optics::PsfSimulator(one).compute(h).psf[0];
  }
  CHECK((band.psf - manual).abs().max().item<double>() < 1e-12);
  CHECK((band.psf.sum({2, 3}) - 1.0).abs().max().item<double>() < 1e-12);
  // K = 1 is the band centre.
  auto centre = spec;
  centre.spectral_samples = 1;
  auto mono = test::make_spec(spec.wavelengths_m, spec.depths_m, N, pitch, 0.25e-3, 11, 5e-6, 0.03, 2);
  CHECK(optics::PsfSimulator(centre).compute(h).psf.equal(optics::PsfSimulator(mono).compute(h).psf));
  // Missing indices are refused.
  auto bad = spec;
  bad.spectral_refractive_index.pop_back();
  CHECK_THROWS_AS(optics::PsfSimulator(bad), InputError);
}

TEST_CASE("gradients with oversampling, spectral samples and sinc cells match finite differences", "[psf][gradient]") {
  const int64_t N = 10;
  auto spec = test::make_spec({500e-9}, {0.3}, N, 10e-6, 0.09e-3, 5, 8e-6, 0.02, 2);
  spec.pupil_oversampling = 2;
  spec.spectral_samples = 2;
  spec.band_width_m = 40e-9;
  spec.spectral_refractive_index = {1.46, 1.455};
  const torch::Tensor h0 = optics::random_height(N, 1.0e-6, 3);
  const torch::Tensor w = torch::randn({1, 1, 5, 5}, torch::kFloat64);
  for (double tol : {1e-6, 0.0}) {  // low-rank and exact kernels, both with the cross term (G = 2)
  spec.mft_rank_tol = tol;
  const optics::PsfSimulator sim(spec);
  auto loss = [&](const torch::Tensor& h) { return (sim.compute(h).psf * w).sum(); };
  torch::Tensor h = h0.clone().set_requires_grad(true);
  loss(h).backward();
  const torch::Tensor g = h.grad();
  torch::NoGradGuard ng;
  const double eps = 1e-10;
  for (auto ij : std::vector<std::pair<int, int>>{{4, 4}, {5, 3}, {2, 6}}) {
    torch::Tensor hp = h0.clone(), hm = h0.clone();
    hp[ij.first][ij.second] += eps;
    hm[ij.first][ij.second] -= eps;
    const double fd = (loss(hp).item<double>() - loss(hm).item<double>()) / (2 * eps);
    const double ad = g[ij.first][ij.second].item<double>();
    INFO("rank tol " << tol << ", sample " << ij.first << "," << ij.second << ": autograd " << ad << ", finite difference " << fd);
    CHECK(ad == Approx(fd).epsilon(1e-5).margin(1e-6 * g.abs().max().item<double>()));
  }
  }
}

namespace {
struct LeaveOutCase {
  optics::PsfSpec spec;
  optics::SensorModel model;
  torch::Tensor h;
};
LeaveOutCase leave_out_case() {
  LeaveOutCase c;
  c.spec = test::make_spec({450e-9, 500e-9, 550e-9, 600e-9, 650e-9}, {0.4, 0.8, 2.0}, 24, 10e-6, 0.22e-3, 9, 8e-6,
                           0.03, 2, torch::kFloat64);
  c.model.omega = optics::camera_response("canon_5d_mark_iii", c.spec.wavelengths_m, 50e-9).to(torch::kFloat64);
  c.model.mask_sigma_px = 1.0;
  c.h = optics::fresnel_height(24, 10e-6, 550e-9, 1.5, 0.8, 0.03);
  return c;
}
optics::LeaveOut nothing_left_out() {
  optics::LeaveOut l;
  l.layers = l.bands = false;
  l.band_tol = l.psf_crop_tol = 0.0;
  return l;
}
double rel_diff(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>() / b.abs().max().item<double>();
}
}  // namespace

TEST_CASE("leave-out: skipped layers, bands, PSF pixels and masked regions equal the full computation",
          "[sensor][leave-out]") {
  const auto c = leave_out_case();
  const optics::PsfSimulator sim(c.spec);
  const int64_t H = 40, W = 36, L = 5;
  torch::manual_seed(3);
  const torch::Tensor rad = torch::rand({2, L, H, W}, torch::kFloat64);
  torch::Tensor depth = torch::full({2, 1, H, W}, 0.4, torch::kFloat64);
  depth.narrow(3, 0, 10).fill_(2.0);  // two of the three layers
  auto sim_img = [&](const torch::Tensor& r, const torch::Tensor& d, const optics::LeaveOut& l) {
    torch::NoGradGuard ng;
    return optics::simulate_sensor(sim, c.model, c.h, r, d, c10::nullopt, l);
  };
  const optics::LeaveOut all = nothing_left_out();

  SECTION("empty layers") {
    const auto full = sim_img(rad, depth, all), lean = sim_img(rad, depth, optics::LeaveOut());
    CHECK(lean.layers == std::vector<int64_t>{0, 2});
    CHECK(full.layers.size() == 3);
    CHECK(rel_diff(lean.clean, full.clean) <= 1e-6);
  }
  SECTION("bands that are exactly dark, and a contribution bound") {
    torch::Tensor mono = torch::zeros_like(rad);
    mono.select(1, 2).copy_(rad.select(1, 2));
    optics::LeaveOut exact;
    exact.band_tol = 0.0;  // only exact zeros
    const auto lean = sim_img(mono, depth, exact);
    CHECK(lean.bands == std::vector<int64_t>{2});
    CHECK(rel_diff(lean.clean, sim_img(mono, depth, all).clean) <= 1e-12);
    // Nearly dark bands: skipped only while the bound holds, and the result stays within it.
    torch::Tensor dim = rad.clone();
    dim.select(1, 0).mul_(1e-9);
    dim.select(1, 4).mul_(1e-3);
    optics::LeaveOut tol;
    tol.band_tol = 1e-6;
    const auto t = sim_img(dim, depth, tol);
    CHECK(t.bands == std::vector<int64_t>{1, 2, 3, 4});
    const auto f = sim_img(dim, depth, all);
    // per image and channel: within the bound times that image's mean signal in that channel
    const torch::Tensor diff = (t.clean - f.clean).abs().amax({2, 3}), mean = f.clean.mean({2, 3});
    CHECK((diff <= 1e-6 * mean).all().item<bool>());
  }
  SECTION("PSF pixels with little light, without a gradient") {
    // Diffraction tails hold more than 1e-7 of the light in any small window
    // (the default never crops these PSFs); a coarser bound does crop a
    // window that is large for the PSF (20-µm pixels, 21-px window).
    CHECK(optics::psf_support_window(sim.compute(c.h).psf, 1e-7) == c.spec.psf_size);
    auto wide = c.spec;
    wide.pixel_pitch_m = 20e-6;
    wide.psf_size = 21;
    const optics::PsfSimulator wsim(wide);
    const double tol = 0.1;
    const int64_t w = optics::psf_support_window(wsim.compute(c.h).psf, tol);
    INFO("support window " << w);
    REQUIRE(w < wide.psf_size);
    optics::LeaveOut crop;
    crop.psf_crop_tol = tol;
    torch::NoGradGuard ng;
    const auto lean = optics::simulate_sensor(wsim, c.model, c.h, rad, depth, c10::nullopt, crop);
    const auto full = optics::simulate_sensor(wsim, c.model, c.h, rad, depth, c10::nullopt, all);
    CHECK(lean.psf.size(2) == w);
    // each PSF loses at most tol of its light: no pixel moves by more than tol · max I · Σ_λ Ω_c,λ
    const double bound = tol * rad.max().item<double>() * c.model.omega.sum(1).max().item<double>();
    CHECK((lean.clean - full.clean).abs().max().item<double>() <= bound);
    CHECK((lean.clean - full.clean).abs().max().item<double>() > 0.0);  // it did change something
  }
  SECTION("with a gradient to the height map nothing is cropped") {
    optics::LeaveOut crop;
    crop.psf_crop_tol = 0.5;
    torch::Tensor h = c.h.clone().set_requires_grad(true);
    CHECK(optics::simulate_sensor(sim, c.model, h, rad, depth, c10::nullopt, crop).psf.size(2) == c.spec.psf_size);
  }
  SECTION("masked-out regions") {
    torch::Tensor valid = torch::zeros({2, 1, H, W}, torch::kFloat64);
    valid.narrow(2, 22, 10).narrow(3, 20, 12).fill_(1.0);
    optics::LeaveOut masked;
    masked.valid = valid;
    const auto lean = sim_img(rad, depth, masked), full = sim_img(rad, depth, all);
    CHECK(((lean.clean - full.clean).abs() * valid).max().item<double>() <= 1e-6 * full.clean.abs().max().item<double>());
    CHECK(lean.clean.narrow(2, 0, 5).abs().max().item<double>() == 0.0);  // far from the valid pixels: not computed
    // occlusion compositing needs the PSF reach of the blurred alphas too
    optics::SensorModel occ = c.model;
    occ.occlusion = true;
    torch::NoGradGuard ng;
    const auto lo = optics::simulate_sensor(sim, occ, c.h, rad, depth, c10::nullopt, masked);
    const auto fo = optics::simulate_sensor(sim, occ, c.h, rad, depth, c10::nullopt, all);
    CHECK(((lo.clean - fo.clean).abs() * valid).max().item<double>() <= 1e-6 * fo.clean.abs().max().item<double>());
    // no valid pixel: nothing rendered
    masked.valid = torch::zeros_like(valid);
    CHECK(sim_img(rad, depth, masked).clean.abs().max().item<double>() == 0.0);
  }
}

TEST_CASE("support window of a PSF follows its light", "[sensor][leave-out]") {
  torch::Tensor p = torch::zeros({1, 1, 9, 9}, torch::kFloat64);
  p[0][0][4][4] = 1.0;
  CHECK(optics::psf_support_window(p, 0.0) == 1);
  p[0][0][4][6] = 1e-3;  // Chebyshev radius 2
  p = p / p.sum();
  CHECK(optics::psf_support_window(p, 1e-2) == 1);
  CHECK(optics::psf_support_window(p, 1e-6) == 5);
  p[0][0][0][0] = 1e-12;
  CHECK(optics::psf_support_window(p, 0.0) == 9);
}

TEST_CASE("stiff scenes: dark, constant and saturated scenes stay finite, with finite gradients", "[sensor][stiff]") {
  const auto c = leave_out_case();
  const optics::PsfSimulator sim(c.spec);
  optics::SensorModel m = c.model;
  m.noise.saturation = 1.0;
  const int64_t H = 24, W = 24;
  const torch::Tensor depth = torch::full({1, 1, H, W}, 0.8, torch::kFloat64);  // a single-layer scene
  for (double level : {0.0, 0.3, 1e6}) {
    torch::Tensor h = c.h.clone().set_requires_grad(true);
    const torch::Tensor rad = torch::full({1, 5, H, W}, level, torch::kFloat64);
    const auto img = optics::simulate_sensor(sim, m, h, rad, depth);
    INFO("radiance " << level);
    REQUIRE(torch::isfinite(img.image).all().item<bool>());
    CHECK(img.layers == std::vector<int64_t>{1});
    if (level == 0.0) CHECK(img.image.abs().max().item<double>() == 0.0);
    if (level == 0.3) {  // uniform stays uniform: no border darkening
      const torch::Tensor per_channel = img.clean.amax({2, 3}) - img.clean.amin({2, 3});
      CHECK(per_channel.max().item<double>() < 1e-9 * img.clean.max().item<double>());
    }
    if (level == 1e6) CHECK(img.image.max().item<double>() == 1.0);  // clipped at saturation
    (img.image.sum() + img.clean.sum() * 1e-12).backward();
    REQUIRE(h.grad().defined());
    CHECK(torch::isfinite(h.grad()).all().item<bool>());
  }
}

TEST_CASE("PSF energy leaving the window is reported with numbers", "[psf][stiff]") {
  // A strongly defocused point (flat DOE, near source) in a 5-pixel window.
  auto spec = test::make_spec({550e-9}, {0.05}, 32, 10e-6, 0.3e-3, 5, 5e-6, 0.03, 2);
  const auto out = optics::PsfSimulator(spec).compute(torch::zeros({32, 32}, torch::kFloat64));
  const double e = out.energy_in_window[0][0].item<double>();
  CHECK(e < 0.5);
  CHECK(e > 0.0);
  const auto rep = optics::check_sampling(spec, out.energy_in_window, 0.5);
  bool named = false;
  for (const auto& w : rep.warnings) named |= w.find("reaches the 5-pixel window") != std::string::npos;
  CHECK(named);
  CHECK(torch::isfinite(out.psf).all().item<bool>());
}

TEST_CASE("a PsfSpec built by hand has the config's numerical settings, and band_width_m 0 is the bands' spacing", "[psf][discretisation]") {
  const optics::PsfSpec hand;
  const OpticsConfig o;
  CHECK(hand.mft_rank_tol == o.mft_rank_tol);
  CHECK(hand.spectral_samples == o.spectral_samples);
  CHECK(hand.pupil_oversampling == o.pupil_oversampling);
  CHECK(hand.pupil_cell_integration == o.pupil_cell_integration);
  CHECK(hand.aperture_shape == o.aperture_shape);
  CHECK(hand.recompute_in_backward == (o.psf_backward == PsfBackward::recompute));
  // band_width_m = 0 means what optics.band_width_nm = 0 means.
  auto spec = test::make_spec({500e-9, 530e-9, 560e-9}, {0.5}, 16, 8e-6, 0.1e-3, 5, 5e-6, 0.03, 2);
  OpticsConfig three;
  three.wavelengths_nm = {500, 530, 560};
  CHECK(spec.resolved_band_width_m() == Approx(three.band_width_m()).epsilon(1e-12));
  spec.wavelengths_m = {550e-9};
  three.wavelengths_nm = {550};
  CHECK(spec.resolved_band_width_m() == Approx(three.band_width_m()).epsilon(1e-12));
  spec.band_width_m = 25e-9;
  CHECK(spec.resolved_band_width_m() == 25e-9);
  // Two samples per band need the material's index at each node: refused by name without them.
  spec = test::make_spec({500e-9}, {0.5}, 16, 8e-6, 0.1e-3, 5, 5e-6, 0.03, 2);
  spec.spectral_samples = 2;
  try {
    optics::PsfSimulator sim(spec);
    FAIL("a spec without spectral_refractive_index was accepted");
  } catch (const InputError& e) {
    CHECK(std::string(e.what()).find("spectral_refractive_index") != std::string::npos);
  }
}
