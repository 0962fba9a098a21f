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
    CHECK(point_err.max().item<double>() > 0.03);
  }
}
