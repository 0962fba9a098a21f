// The accuracy target of the PSF simulator at the paper's default settings:
// ≤ 1% mean and ≤ 3% worst relative L1 error over all (λ, z), against a
// converged float64 computation (8 Gauss nodes per pixel axis). Point-sampled
// pixels (1 node), the usual shortcut, are shown to miss that target.
#include <catch2/catch.hpp>

#include "common/config.h"
#include "helpers.h"
#include "optics/doe.h"

using namespace hsd;

namespace {
// relative L1 per (λ, z) slice: Σ|a − b| / Σ|b|
torch::Tensor rel_l1(const torch::Tensor& a, const torch::Tensor& ref) {
  return (a.to(torch::kFloat64) - ref).abs().sum({2, 3}) / ref.abs().sum({2, 3});
}
}  // namespace

TEST_CASE("paper defaults meet the PSF accuracy target", "[psf][accuracy]") {
  for (const char* init : {"fresnel", "spiral"}) {
    const Config cfg = load_config(test::source_path("configs/paper.json"), {std::string("optics.doe.init=") + init});
    const auto material = optics::Material::load(cfg.optics.material);
    const torch::Tensor h = optics::make_doe(cfg.optics, material, cfg.seed, torch::kCPU).height().detach();
    torch::NoGradGuard ng;

    auto spec = optics::make_psf_spec(cfg.optics, material, torch::kCPU);
    const auto fast = optics::PsfSimulator(spec).compute(h).psf;

    auto ref_spec = spec;
    ref_spec.real_dtype = torch::kFloat64;
    ref_spec.pixel_nodes.assign(spec.pixel_nodes.size(), 8);
    ref_spec.mft_rank_tol = 0.0;  // exact matrix Fourier transform
    const auto ref = optics::PsfSimulator(ref_spec).compute(h).psf;

    const torch::Tensor err = rel_l1(fast, ref);
    const double mean = err.mean().item<double>(), worst = err.max().item<double>();
    INFO(init << ": relative L1 mean " << mean << ", worst " << worst);
    CHECK(mean <= 0.01);
    CHECK(worst <= 0.03);

    auto point_spec = spec;
    point_spec.pixel_nodes.assign(spec.pixel_nodes.size(), 1);
    const torch::Tensor point_err = rel_l1(optics::PsfSimulator(point_spec).compute(h).psf, ref);
    INFO(init << ": point-sampled pixels: mean " << point_err.mean().item<double>() << ", worst "
              << point_err.max().item<double>());
    CHECK(point_err.max().item<double>() > worst);
    CHECK((point_err.mean().item<double>() > 0.01 || point_err.max().item<double>() > 0.03));  // misses the target
  }
}

TEST_CASE("low-rank window kernels match the exact MFT and keep far fewer ranks than rows", "[psf][accuracy]") {
  const Config cfg = load_config(test::source_path("configs/paper.json"), {"optics.doe.init=spiral"});
  const auto material = optics::Material::load(cfg.optics.material);
  const torch::Tensor h = optics::make_doe(cfg.optics, material, cfg.seed, torch::kCPU).height().detach();
  auto spec = optics::make_psf_spec(cfg.optics, material, torch::kCPU);
  spec.real_dtype = torch::kFloat64;
  spec.wavelengths_m = {420e-9, 540e-9, 660e-9};
  spec.spectral_samples = 1;
  spec.refractive_index = material.indices(spec.wavelengths_m);
  spec.pixel_nodes = {3, 3, 2};
  auto exact_spec = spec;
  exact_spec.mft_rank_tol = 0.0;
  torch::NoGradGuard ng;
  const optics::PsfSimulator low(spec), exact(exact_spec);
  const auto a = low.compute(h), b = exact.compute(h);
  const double err = rel_l1(a.psf, b.psf).max().item<double>();
  INFO("low-rank vs exact worst relative L1: " << err);
  CHECK(err < 1e-5);
  CHECK((a.energy_in_window - b.energy_in_window).abs().max().item<double>() < 1e-6);
  // rank near the time-bandwidth product 2X·D/(λs) (+ a few), far below M = P·n
  const auto ranks = low.kernel_ranks();
  for (size_t l = 0; l < ranks.size(); ++l) {
    const double X = 0.5 * spec.psf_size * spec.pixel_pitch_m;
    const double tbp = 2.0 * X * spec.aperture_diameter_m / (spec.wavelengths_m[l] * spec.sensor_distance_m);
    INFO("band " << l << ": rank " << ranks[l] << ", time-bandwidth product " << tbp);
    CHECK(double(ranks[l]) > tbp);
    CHECK(double(ranks[l]) < tbp + 40.0);
    CHECK(ranks[l] < spec.psf_size * spec.pixel_nodes[l] / 2);
  }
}
