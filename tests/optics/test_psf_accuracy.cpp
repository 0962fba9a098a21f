// The accuracy target of the PSF simulator at the paper's default settings:
// ≤ 1% mean and ≤ 3% worst relative L1 error over all (λ, z), against a
// converged float64 computation (8 Gauss nodes per pixel axis). Point-sampled
// pixels (1 node), the usual shortcut, are shown to miss that target.
#include <catch2/catch.hpp>

#include "common/config.h"
#include "helpers.h"
#include "optics/doe.h"
#include "optics/fresnel_mft.h"

using namespace hsd;

namespace {
// relative L1 per (λ, z) slice: Σ|a − b| / Σ|b|
torch::Tensor rel_l1(const torch::Tensor& a, const torch::Tensor& ref) {
  return (a.to(torch::kFloat64) - ref).abs().sum({2, 3}) / ref.abs().sum({2, 3});
}
// The paper geometry in float64 at three band centres (420, 540, 660 nm; 3, 3
// and 2 pixel nodes; no spectral samples), and its spiral DOE's heights.
std::pair<optics::PsfSpec, torch::Tensor> three_band_paper_spiral() {
  const Config cfg = load_config(test::source_path("configs/paper.json"), {"optics.doe.init=spiral"});
  const auto material = optics::Material::load(cfg.optics.material);
  auto spec = optics::make_psf_spec(cfg.optics, material, torch::kCPU);
  spec.real_dtype = torch::kFloat64;
  spec.wavelengths_m = {420e-9, 540e-9, 660e-9};
  spec.spectral_samples = 1;
  spec.refractive_index = material.indices(spec.wavelengths_m);
  spec.pixel_nodes = {3, 3, 2};
  return {spec, optics::make_doe(cfg.optics, material, cfg.seed, torch::kCPU).height().detach()};
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

    const auto ref_spec = optics::converged_reference(spec);
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
  const auto [spec0, h] = three_band_paper_spiral();
  auto spec = spec0;
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

TEST_CASE("the window kernel's factors from the Gram matrix are the truncated SVD's", "[psf][accuracy]") {
  // The paper's geometry: 63 pixels x 2 nodes at 6.22 um, 512 pupil samples at 4 um, s = 50 mm.
  const torch::Tensor x = (torch::arange(126, torch::kFloat64) - 62.5) * (6.22e-6 / 2.0);
  const torch::Tensor xi = (torch::arange(512, torch::kFloat64) - 255.5) * 4e-6;
  for (double lambda : {420e-9, 550e-9, 660e-9}) {
    const torch::Tensor T = optics::compute_tilt_kernel(x, xi, lambda, 0.05, torch::kComplexDouble);
    const torch::Tensor S = torch::linalg_svdvals(T);
    for (double tol : {1e-3, 1e-4, 1e-6}) {
      INFO("lambda " << lambda << ", tol " << tol);
      const optics::LowRankKernel k = optics::factor_tilt_kernel(T, tol, torch::kComplexDouble);
      const int64_t r = k.left.size(1), r_svd = (S > tol * S[0].item<double>()).sum().item<int64_t>();
      CHECK(std::abs(r - r_svd) <= 1);  // a singular value at the cut may fall either side of it
      // The error of the truncation is the first discarded singular value (Eckart-Young).
      const double err = torch::linalg_matrix_norm(T - torch::mm(k.left, k.right), 2).item<double>();
      CHECK(err <= 1.05 * S[r].item<double>() + 1e-12 * S[0].item<double>());
      CHECK(err < tol * S[0].item<double>() * 1.05);
    }
  }
}

TEST_CASE("the joint depth basis matches the per-depth kernels with about one depth's rank", "[psf][accuracy]") {
  const auto [spec0, h] = three_band_paper_spiral();
  auto spec = spec0;
  REQUIRE(spec.depths_m.size() == 7);
  REQUIRE(spec.cell_kernel_terms() == 2);  // sinc_cross: two kernel terms per depth
  auto joint_spec = spec, exact_spec = spec;
  joint_spec.depth_basis = true;
  exact_spec.mft_rank_tol = 0.0;
  torch::NoGradGuard ng;
  const optics::PsfSimulator per_depth(spec), joint(joint_spec), exact(exact_spec);
  const auto a = joint.compute(h), b = per_depth.compute(h), c = exact.compute(h);
  const double err_low = rel_l1(a.psf, b.psf).max().item<double>(), err_exact = rel_l1(a.psf, c.psf).max().item<double>();
  INFO("joint vs per-depth low rank: " << err_low << ", joint vs exact MFT: " << err_exact);
  CHECK(err_low < 1e-5);
  CHECK(err_exact < 2e-5);
  CHECK((a.energy_in_window - c.energy_in_window).abs().max().item<double>() < 1e-6);
  // A subset of depths, in any order, is the full stack's slices (the basis spans every depth).
  const auto sub = joint.compute(h, {5, 1});
  CHECK(torch::allclose(sub.psf, a.psf.index_select(1, torch::tensor({5, 1})), 0.0, 1e-14));
  // Rank: at most one depth's two kernel terms (2r), far below the Z·2r rows of the per-depth products.
  const auto R = joint.depth_basis_ranks(), r = joint.kernel_ranks();
  for (size_t l = 0; l < R.size(); ++l) {
    INFO("band " << l << ": joint rank " << R[l] << ", one depth's rank " << r[l] << " (x2 terms), 7 depths " << 14 * r[l]);
    CHECK(R[l] > r[l]);
    CHECK(R[l] <= 2 * r[l]);
  }
  CHECK(per_depth.depth_basis_ranks() == std::vector<int64_t>(3, 0));
}

TEST_CASE("the joint depth basis is the stacked kernels' truncated SVD", "[psf][accuracy]") {
  // The paper's geometry at 550 nm: 63 pixels x 2 nodes, 512 pupil samples, 7 depths 0.4-2 m.
  const torch::Tensor x = (torch::arange(126, torch::kFloat64) - 62.5) * (6.22e-6 / 2.0);
  const torch::Tensor xi = (torch::arange(512, torch::kFloat64) - 255.5) * 4e-6;
  const torch::Tensor T = optics::compute_tilt_kernel(x, xi, 550e-9, 0.05, torch::kComplexDouble);
  std::vector<torch::Tensor> ks;
  for (double z : {0.4, 0.4615, 0.5455, 0.6667, 0.8571, 1.2, 2.0})
    ks.push_back(T * optics::compute_defocus_chirp(xi, 550e-9, z, 0.05, torch::kComplexDouble).view({1, -1}));
  const torch::Tensor K = torch::stack(ks);  // [7, 126, 512]
  const torch::Tensor X = K.reshape({-1, 512});
  const torch::Tensor S = torch::linalg_svdvals(X);
  for (double tol : {1e-3, 1e-4, 1e-6}) {
    INFO("tol " << tol);
    const optics::DepthBasis d = optics::factor_depth_kernels(K, tol, torch::kComplexDouble);
    const int64_t R = d.basis.size(0), r_svd = (S > tol * S[0].item<double>()).sum().item<int64_t>();
    CHECK(std::abs(R - r_svd) <= 1);
    CHECK(torch::allclose(torch::mm(d.basis, d.basis.conj().t()), torch::eye(R, d.basis.options()), 0.0, 1e-10));
    // Eckart-Young: the stack's error is its first discarded singular value.
    const double err = torch::linalg_matrix_norm(X - torch::mm(d.left.reshape({-1, R}), d.basis), 2).item<double>();
    CHECK(err <= 1.05 * S[R].item<double>() + 1e-12 * S[0].item<double>());
    CHECK(err < 1.05 * tol * S[0].item<double>());
  }
}
