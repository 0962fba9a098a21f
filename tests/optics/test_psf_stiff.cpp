// Stiff and extreme cases: each gives a finite, correct result or a clear
// refusal; never NaN silently.
#include <catch2/catch.hpp>
#include <cmath>

#include "common/config.h"
#include "common/error.h"
#include "common/log.h"
#include "helpers.h"
#include "optics/doe.h"
#include "optics/sampling_check.h"

using namespace hsd;

namespace {
bool finite_and_normalised(const optics::PsfStack& out) {
  return torch::isfinite(out.psf).all().item<bool>() && torch::isfinite(out.energy_in_window).all().item<bool>() &&
         (out.psf.sum({2, 3}) - 1.0).abs().max().item<double>() < 1e-4;
}
}  // namespace

TEST_CASE("a source at 1e6 m behaves like one at infinity", "[psf][stiff]") {
  const int64_t N = 64;
  auto spec = test::make_spec({550e-9}, {1e6, 1e12}, N, 8e-6, 0.5e-3, 15, 4e-6, 0.05, 3, torch::kFloat32);
  const torch::Tensor h = optics::fresnel_height(N, 8e-6, 550e-9, 1.5, 1e6, 0.05);
  const auto out = optics::PsfSimulator(spec).compute(h);
  REQUIRE(finite_and_normalised(out));
  CHECK((out.psf[0][0] - out.psf[0][1]).abs().max().item<double>() < 1e-5);
}

TEST_CASE("a source very close to the DOE is finite and flagged as undersampled", "[psf][stiff]") {
  const int64_t N = 64;
  auto spec = test::make_spec({450e-9}, {0.002, 0.5}, N, 8e-6, 0.5e-3, 15, 4e-6, 0.05, 3, torch::kFloat32);
  const optics::PsfSimulator sim(spec);
  const torch::Tensor h = torch::zeros({N, N}, torch::kFloat64);
  const auto out = sim.compute(h);
  REQUIRE(finite_and_normalised(out));
  const auto rep = optics::check_sampling(spec, out.energy_in_window, 0.5);
  CHECK(rep.max_phase_step_rad[0][0].item<double>() > M_PI);   // 2 mm: undersampled, and said so
  CHECK(rep.max_phase_step_rad[0][1].item<double>() < M_PI);   // 0.5 m: fine
  bool named = false;
  for (const auto& w : rep.warnings) named |= w.find("undersampled") != std::string::npos && w.find("0.002") != std::string::npos;
  CHECK(named);
}

TEST_CASE("wavelengths at 380 and 780 nm are finite and warn about the dispersion range", "[psf][stiff]") {
  const auto noa61 = optics::Material::load("noa61_norland");  // valid 450-1550 nm
  const int before = log::warning_count();
  const auto n = noa61.indices({380e-9, 780e-9});
  CHECK(log::warning_count() == before + 1);
  CHECK(n[0] > n[1]);
  const int64_t N = 64;
  auto spec = test::make_spec({380e-9, 780e-9}, {0.5, 2.0}, N, 8e-6, 0.5e-3, 15, 4e-6, 0.05, 3, torch::kFloat32);
  spec.refractive_index = n;
  const auto out = optics::PsfSimulator(spec).compute(optics::fresnel_height(N, 8e-6, 550e-9, n[0], 1.0, 0.05));
  CHECK(finite_and_normalised(out));
}

TEST_CASE("heights of many 2pi periods keep float32 phases exact", "[psf][stiff]") {
  // Adding 1000 periods at λ0 leaves the phase at λ0 unchanged mod 2π. Built in
  // float32 the phase would lose ~1e-3 rad per sample; built in float64 and
  // wrapped it does not.
  const int64_t N = 64;
  const double lambda0 = 550e-9, n0 = 1.46;
  auto spec = test::make_spec({lambda0}, {1.0}, N, 8e-6, 0.5e-3, 15, 4e-6, 0.05, 3, torch::kFloat32, n0);
  const optics::PsfSimulator sim(spec);
  const torch::Tensor h = optics::fresnel_height(N, 8e-6, lambda0, n0, 1.0, 0.05);
  const double period = lambda0 / (n0 - 1.0);
  const auto a = sim.compute(h).psf;
  const auto b = sim.compute(h + 1000.0 * period).psf;
  REQUIRE(torch::isfinite(b).all().item<bool>());
  CHECK((a - b).abs().max().item<double>() < 1e-5 * a.max().item<double>() * 10);
}

TEST_CASE("a 3-pixel window and an aperture that fills the grid are fine", "[psf][stiff]") {
  const int64_t N = 32;
  auto spec = test::make_spec({500e-9, 600e-9}, {0.5}, N, 10e-6, 0.32e-3, 3, 6e-6, 0.05, 2, torch::kFloat32);
  const auto out = optics::PsfSimulator(spec).compute(optics::random_height(N, 1e-6, 1));
  CHECK(out.psf.sizes() == torch::IntArrayRef({2, 1, 3, 3}));
  CHECK(finite_and_normalised(out));
  spec.aperture_shape = ApertureShape::square;
  CHECK(finite_and_normalised(optics::PsfSimulator(spec).compute(optics::random_height(N, 1e-6, 2))));
}

TEST_CASE("bad PSF inputs are refused with a message", "[psf][stiff]") {
  auto spec = test::make_spec({500e-9}, {0.5}, 16, 10e-6, 0.1e-3, 5, 6e-6, 0.05, 2);
  const optics::PsfSimulator sim(spec);
  CHECK_THROWS_AS(sim.compute(torch::zeros({8, 8}, torch::kFloat64)), InputError);
  CHECK_THROWS_AS(sim.compute(torch::zeros({16, 16}, torch::kFloat64), {3}), InputError);
  torch::Tensor bad = torch::zeros({16, 16}, torch::kFloat64);
  bad[8][8] = std::nan("");
  CHECK_THROWS_AS(sim.compute(bad), NumericalError);
  auto even = spec;
  even.psf_size = 4;
  CHECK_THROWS_AS(optics::PsfSimulator(even), InputError);
}

TEST_CASE("the paper geometry is adequately sampled and the check follows its closed form", "[psf][stiff]") {
  const Config cfg = load_config(test::source_path("configs/paper.json"), {});
  const auto spec = optics::make_psf_spec(cfg.optics, optics::Material::load(cfg.optics.material), torch::kCPU);
  const auto rep = optics::check_sampling(spec, torch::Tensor(), 0.5);
  CHECK(rep.warnings.empty());
  // k δ (D/2 · (1/z + 1/s) + x_edge/s) at 420 nm and the nearest depth, with D/2 + δ/2
  const double k = 2 * M_PI / 420e-9, d = cfg.optics.doe_pitch_m;
  const double expected = k * d * ((0.5 * cfg.optics.aperture_diameter_m + 0.5 * d) * (1.0 / 0.4 + 1.0 / 0.05) +
                                   0.5 * cfg.optics.psf_size * cfg.optics.pixel_pitch_m / 0.05);
  CHECK(rep.max_phase_step_rad.max().item<double>() == Approx(expected).epsilon(1e-9));
  CHECK(rep.max_phase_step_rad.max().item<double>() < M_PI);
  for (double period : rep.period_pixels) CHECK(period > double(cfg.optics.psf_size));
}
