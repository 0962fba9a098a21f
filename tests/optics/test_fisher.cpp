// Fisher information and CRLB: the textbook bound of a Gaussian spot whose
// width is the parameter (Poisson noise), autograd derivatives of the PSF
// against finite differences, Zernike orthonormality, a design that lowers
// the CRLB below its (Fresnel) start, and symmetric cases without NaN.
#include <catch2/catch.hpp>
#include <cmath>

#include "common/error.h"
#include "helpers.h"
#include "optics/doe.h"
#include "optics/fisher.h"
#include "optics/fisher_design.h"
#include "optics/zernike.h"

using namespace hsd;
using torch::indexing::None;

namespace {
// A small geometry: 48 DOE samples of 10 µm (0.44 mm aperture), 11-px window of 10 µm, s = 20 mm.
optics::FisherGeometry small_geometry(optics::PsfSpec* out = nullptr) {
  auto spec = test::make_spec({500e-9, 600e-9}, {0.3, 1.0}, 48, 10e-6, 0.44e-3, 11, 10e-6, 0.02, 2);
  if (out) *out = spec;
  return optics::make_fisher_geometry(spec, 11, 2);
}
optics::FisherSettings small_settings() {
  optics::FisherSettings s;
  s.photons = 2000, s.background = 2;
  s.wavelengths_nm = {500, 600};
  s.depths_m = {0.3, 1.0};
  s.inv_depth_spacing = 1.0 / 0.3 - 1.0;
  s.band_width_nm = 100;
  return s;
}
}  // namespace

TEST_CASE("fisher: a Gaussian spot of width sigma has the textbook CRLB sigma over 2 sqrt(N)", "[fisher]") {
  // μ(x, y) = N g(x, y; σ) on a fine grid (pixel 0.1 σ, ±8 σ); for Poisson noise
  // without background I(σ) = 4N/σ², so CRLB(σ) = σ / (2 √N).
  const double N = 1e4, sigma0 = 1.0;
  const torch::Tensor sigma = torch::tensor(sigma0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor x = torch::arange(-8.0, 8.0, 0.1, torch::kFloat64) + 0.05;
  const torch::Tensor r2 = x.view({1, -1}).pow(2) + x.view({-1, 1}).pow(2);
  const torch::Tensor mu = N * 0.01 * torch::exp(-r2 / (2.0 * sigma * sigma)) / (2.0 * M_PI * sigma * sigma);
  const auto J = optics::jacobian_by_autograd(mu, {sigma}, false);
  const torch::Tensor I = optics::fisher_from_jacobian(mu, J, 0.0);
  CHECK(I[0][0].item<double>() == Approx(4.0 * N / (sigma0 * sigma0)).epsilon(1e-3));
  const optics::Crlb c = optics::crlb_from_fisher(I);
  CHECK(c.crlb[0].item<double>() == Approx(sigma0 / (2.0 * std::sqrt(N))).epsilon(1e-3));
  // Background only adds noise: the bound grows.
  CHECK(optics::crlb_from_fisher(optics::fisher_from_jacobian(mu, J, 1.0)).crlb[0].item<double>() > c.crlb[0].item<double>());
}

TEST_CASE("fisher: autograd derivatives of the PSF match finite differences", "[fisher]") {
  optics::PsfSpec spec;
  const auto g = small_geometry(&spec);
  const torch::Tensor h = optics::fresnel_height(48, 10e-6, 550e-9, 1.46, 0.5, 0.02).to(torch::kFloat64);
  const double eta0 = 1.46, deta = -3e-5;  // per nm
  const double D0 = 2.6, L0 = 550.0;  // off focus (the lens focuses D = 2 at 550 nm, where dPSF/dD = 0 by symmetry)
  auto psf_at = [&](double D, double L) {
    return optics::point_psf(g, h, torch::tensor(D, torch::kFloat64), torch::tensor(L, torch::kFloat64), eta0 + (L - L0) * deta, deta);
  };
  const torch::Tensor D = torch::tensor(D0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor L = torch::tensor(L0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor mu = optics::point_psf(g, h, D, L, eta0, deta);
  const auto J = optics::jacobian_by_autograd(mu, {D, L}, false);
  const double eD = 1e-4, eL = 1e-3;
  const torch::Tensor fdD = (psf_at(D0 + eD, L0) - psf_at(D0 - eD, L0)) / (2 * eD);
  const torch::Tensor fdL = (psf_at(D0, L0 + eL) - psf_at(D0, L0 - eL)) / (2 * eL);
  REQUIRE(J[0].abs().max().item<double>() > 0);
  INFO("max dmu/dD " << J[0].abs().max().item<double>() << " err " << (J[0] - fdD).abs().max().item<double>() << "; max dmu/dlambda " << J[1].abs().max().item<double>() << " err " << (J[1] - fdL).abs().max().item<double>());
  CHECK((J[0] - fdD).abs().max().item<double>() < 1e-6 * J[0].abs().max().item<double>());
  CHECK((J[1] - fdL).abs().max().item<double>() < 1e-5 * J[1].abs().max().item<double>());
}

TEST_CASE("fisher: Zernike modes are orthonormal over the disk", "[fisher]") {
  const int64_t n = 256;
  const torch::Tensor Z = optics::zernike_basis(1, 15, n, 1.0 / n, 1.0).view({15, -1});
  const torch::Tensor inside = (optics::zernike_basis(1, 1, n, 1.0 / n, 1.0).view(-1) != 0).to(torch::kFloat64);
  const torch::Tensor gram = torch::mm(Z, Z.t()) / inside.sum();
  CHECK((gram - torch::eye(15, torch::kFloat64)).abs().max().item<double>() < 0.02);
}

TEST_CASE("fisher: the design lowers the CRLB below the Fresnel start, and symmetric cases stay finite", "[fisher]") {
  optics::PsfSpec spec;
  const auto g = small_geometry(&spec);
  const auto s = small_settings();
  const auto material = optics::Material::constant(1.46);
  const double hmax = 550e-9 / 0.46;
  const torch::Tensor start = optics::fresnel_lens_height(48, 10e-6, 550e-9, 1.46, 0.5, 0.02);
  const torch::Tensor fresnel = optics::fresnel_height(48, 10e-6, 550e-9, 1.46, 0.5, 0.02).to(torch::kFloat64);
  const double a_fresnel = optics::crlb_report(g, material, fresnel, s).aggregate.item<double>();
  FisherConfig cfg;
  cfg.steps = 12;
  cfg.zernike_modes = 10;
  cfg.lr = 0.05;
  const optics::FisherDesign d = optics::design_fisher_doe(g, material, s, start, hmax, cfg);
  CHECK(d.start_aggregate == Approx(a_fresnel).epsilon(1e-9));  // the start is the Fresnel DOE
  CHECK(d.final_aggregate < d.start_aggregate);
  CHECK(d.final_aggregate < a_fresnel);
  const double recheck = optics::crlb_report(g, material, d.height_m, s).aggregate.item<double>();
  CHECK(recheck == Approx(d.final_aggregate).epsilon(1e-9));
  CHECK(d.height_m.min().item<double>() >= 0.0);
  CHECK(d.height_m.max().item<double>() < hmax);
  // Free-form: one height offset per sample; also lowers the bound, and maps to a finer grid.
  FisherConfig ff = cfg;
  ff.basis = FisherBasis::freeform;
  ff.steps = 6;
  ff.lr = 0.01;
  const optics::FisherDesign f = optics::design_fisher_doe(g, material, s, start, hmax, ff);
  CHECK(f.final_aggregate < f.start_aggregate);
  const torch::Tensor fine = optics::design_height_on_grid(
      f, optics::fresnel_lens_height(96, 5e-6, 550e-9, 1.46, 0.5, 0.02), 96, 5e-6, 0.44e-3, hmax);
  CHECK(fine.sizes() == torch::IntArrayRef({96, 96}));
  CHECK(fine.min().item<double>() >= 0.0);
  CHECK(fine.max().item<double>() < hmax);
  // The Zernike design re-evaluated on its own grid is the design.
  CHECK((optics::design_height_on_grid(d, start, 48, 10e-6, 0.44e-3, hmax) - d.height_m).abs().max().item<double>() < 1e-15);
  // A flat DOE (rotationally symmetric PSF) and no background: finite, condition reported.
  optics::FisherSettings s0 = s;
  s0.background = 0.0;
  const optics::CrlbReport flat = optics::crlb_report(g, material, torch::zeros({48, 48}, torch::kFloat64), s0);
  CHECK(torch::isfinite(flat.crlb_inv_depth).all().item<bool>());
  CHECK(torch::isfinite(flat.crlb_wavelength_nm).all().item<bool>());
  CHECK(std::isfinite(flat.aggregate.item<double>()));
  CHECK(flat.max_condition >= 1.0);
  // A singular Fisher matrix (one parameter has no effect): finite, condition inf.
  const optics::Crlb sing = optics::crlb_from_fisher(torch::tensor({4.0, 0.0, 0.0, 0.0}, torch::kFloat64).view({2, 2}));
  CHECK(torch::isfinite(sing.crlb).all().item<bool>());
  CHECK(std::isinf(sing.condition));
}

namespace {
// μ = N·0.01·g(x − cx − shift(p), y − cy; σ(p)) on a fine grid (pixel 0.1): a Gaussian spot.
torch::Tensor gaussian_spot(const torch::Tensor& sigma, const torch::Tensor& cx, const torch::Tensor& cy, double N) {
  const torch::Tensor x = torch::arange(-8.0, 8.0, 0.1, torch::kFloat64) + 0.05;
  const torch::Tensor dx = x.view({1, -1}) - cx, dy = x.view({-1, 1}) - cy;
  return N * 0.01 * torch::exp(-(dx * dx + dy * dy) / (2.0 * sigma * sigma)) / (2.0 * M_PI * sigma * sigma);
}
}  // namespace

TEST_CASE("fisher nuisance: an unknown centre leaves a width's bound alone and erases a shift's", "[fisher]") {
  const double N = 1e4;
  // Width encodes the parameter, centre unknown: ∂μ/∂σ is even, ∂μ/∂c odd, so
  // the cross terms vanish and the bound on σ is unchanged (orthogonal).
  const torch::Tensor sigma = torch::tensor(1.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor cx = torch::tensor(0.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor cy = torch::tensor(0.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor mu = gaussian_spot(sigma, cx, cy, N);
  const torch::Tensor I = optics::fisher_from_jacobian(mu, optics::jacobian_by_autograd(mu, {sigma, cx, cy}, false), 0.0);
  const double known = optics::crlb_from_fisher(I.narrow(0, 0, 1).narrow(1, 0, 1)).crlb[0].item<double>();
  const double unknown = optics::crlb_with_nuisance(I, 1).crlb[0].item<double>();
  CHECK(known == Approx(1.0 / (2.0 * std::sqrt(N))).epsilon(1e-3));
  CHECK(unknown == Approx(known).epsilon(1e-9));
  // The centre moves with the parameter p: μ = g(x − p − cx). Known centre: the
  // textbook bound σ/√N; unknown centre: p and cx cannot be told apart.
  const torch::Tensor p = torch::tensor(0.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor mu2 = gaussian_spot(torch::tensor(1.0, torch::kFloat64), p + cx, cy, N);
  const torch::Tensor I2 = optics::fisher_from_jacobian(mu2, optics::jacobian_by_autograd(mu2, {p, cx, cy}, false), 0.0);
  const double shift_known = optics::crlb_from_fisher(I2.narrow(0, 0, 1).narrow(1, 0, 1)).crlb[0].item<double>();
  const optics::Crlb shift_unknown = optics::crlb_with_nuisance(I2, 1);
  CHECK(shift_known == Approx(1.0 / std::sqrt(N)).epsilon(1e-3));
  CHECK(std::isfinite(shift_unknown.crlb[0].item<double>()));
  CHECK(shift_unknown.crlb[0].item<double>() > 1e3 * shift_known);
  // Brightness that encodes the parameter: μ = (1 + p)·N·g. Known N: informative;
  // with the brightness scale a unknown (μ = a(1 + p)·N·g), no information is left.
  const torch::Tensor a = torch::tensor(1.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor q = torch::tensor(0.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor mu3 = a * (1.0 + q) * gaussian_spot(torch::tensor(1.0, torch::kFloat64), cx, cy, N);
  const torch::Tensor I3 = optics::fisher_from_jacobian(mu3, optics::jacobian_by_autograd(mu3, {q, a}, false), 0.0);
  CHECK(optics::crlb_from_fisher(I3.narrow(0, 0, 1).narrow(1, 0, 1)).crlb[0].item<double>() == Approx(1.0 / std::sqrt(N)).epsilon(1e-3));
  CHECK(optics::crlb_with_nuisance(I3, 1).crlb[0].item<double>() > 1e3 / std::sqrt(N));
}

TEST_CASE("fisher nuisance: the Schur complement's bound is the block of the full inverse", "[fisher]") {
  torch::manual_seed(11);
  for (int64_t n_interest : {1, 2, 4}) {
    const torch::Tensor A = torch::randn({5, 5}, torch::kFloat64);
    const torch::Tensor I = A.mm(A.t()) + 0.5 * torch::eye(5, torch::kFloat64);
    const torch::Tensor full = torch::linalg_inv(I).diagonal().sqrt().narrow(0, 0, n_interest);
    const torch::Tensor schur = optics::crlb_with_nuisance(I, n_interest).crlb;
    CHECK((schur - full).abs().max().item<double>() < 1e-9 * full.abs().max().item<double>());
  }
  // n_interest = K is the plain bound.
  const torch::Tensor I = torch::tensor({4.0, 1.0, 1.0, 3.0}, torch::kFloat64).view({2, 2});
  CHECK(torch::allclose(optics::crlb_with_nuisance(I, 2).crlb, optics::crlb_from_fisher(I).crlb));
  CHECK_THROWS_AS(optics::crlb_with_nuisance(I, 0), InputError);
}

TEST_CASE("fisher nuisance: PSF shifts move +x along columns and +y along rows, autograd matches finite differences", "[fisher]") {
  const auto g = small_geometry();
  const torch::Tensor h = optics::fresnel_height(48, 10e-6, 550e-9, 1.46, 0.5, 0.02).to(torch::kFloat64);
  const double eta0 = 1.46, deta = -3e-5;
  const torch::Tensor D = torch::tensor(2.6, torch::kFloat64), L = torch::tensor(550.0, torch::kFloat64);
  auto psf = [&](double sx, double sy) {
    return optics::point_psf(g, h, D, L, eta0, deta, torch::tensor(sx, torch::kFloat64), torch::tensor(sy, torch::kFloat64));
  };
  const torch::Tensor p0 = optics::point_psf(g, h, D, L, eta0, deta);
  CHECK(torch::allclose(psf(0, 0), p0, 1e-12, 1e-15));
  // A whole-pixel shift is the same PSF moved by that many columns / rows (the nodes land on the same points).
  using torch::indexing::Slice;
  const torch::Tensor right = psf(2, 0), down = psf(0, 1);
  CHECK((right.index({Slice(), Slice(2, None)}) - p0.index({Slice(), Slice(0, -2)})).abs().max().item<double>() <
        1e-9 * p0.max().item<double>());
  CHECK((down.index({Slice(1, None), Slice()}) - p0.index({Slice(0, -1), Slice()})).abs().max().item<double>() <
        1e-9 * p0.max().item<double>());
  // ∂μ/∂x, ∂μ/∂y by autograd against central differences.
  const torch::Tensor sx = torch::tensor(0.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor sy = torch::tensor(0.0, torch::kFloat64).requires_grad_(true);
  const torch::Tensor mu = optics::point_psf(g, h, D, L, eta0, deta, sx, sy);
  const auto J = optics::jacobian_by_autograd(mu, {sx, sy}, false);
  const double e = 1e-4;
  const torch::Tensor fdx = (psf(e, 0) - psf(-e, 0)) / (2 * e), fdy = (psf(0, e) - psf(0, -e)) / (2 * e);
  REQUIRE(J[0].abs().max().item<double>() > 0);
  CHECK((J[0] - fdx).abs().max().item<double>() < 1e-6 * J[0].abs().max().item<double>());
  CHECK((J[1] - fdy).abs().max().item<double>() < 1e-6 * J[1].abs().max().item<double>());
}

TEST_CASE("fisher nuisance: unknown position and brightness never lower a bound, and the capped aggregate resists a singular point", "[fisher]") {
  const auto g = small_geometry();
  const auto material = optics::Material::constant(1.46);
  const torch::Tensor fresnel = optics::fresnel_height(48, 10e-6, 550e-9, 1.46, 0.5, 0.02).to(torch::kFloat64);
  optics::FisherSettings s = small_settings();
  s.wavelengths_nm = {500, 550, 600};
  s.depths_m = {0.3, 0.5, 1.0};  // 0.5 m at 550 nm is the lens's exact focus: ∂μ/∂D = 0 there
  optics::FisherSettings known = s;
  known.nuisance.clear();
  known.aggregate = CrlbAggregate::mean;
  const optics::CrlbReport rn = optics::crlb_report(g, material, fresnel, s);
  const optics::CrlbReport rk = optics::crlb_report(g, material, fresnel, known);
  CHECK((rn.crlb_inv_depth >= rk.crlb_inv_depth * (1 - 1e-9)).all().item<bool>());
  CHECK((rn.crlb_wavelength_nm >= rk.crlb_wavelength_nm * (1 - 1e-9)).all().item<bool>());
  CHECK((rn.crlb_wavelength_nm > rk.crlb_wavelength_nm * 1.0001).any().item<bool>());  // something is lost
  // nuisance [] with the mean is the earlier aggregate: the mean of the per-point terms of a 2×2 Fisher matrix.
  double sum = 0;
  for (int64_t l = 0; l < 3; ++l)
    for (int64_t z = 0; z < 3; ++z) {
      const double u = rk.crlb_inv_depth[l][z].item<double>() / s.inv_depth_spacing, v = rk.crlb_wavelength_nm[l][z].item<double>() / s.band_width_nm;
      sum += std::sqrt((u * u + v * v) / 2);
    }
  CHECK(rk.aggregate.item<double>() == Approx(sum / 9).epsilon(1e-12));
  CHECK(rk.aggregate_mean == Approx(sum / 9).epsilon(1e-12));
  // The in-focus point's bound is far above the others; the mean follows it, the capped mean and median do not.
  INFO("mean " << rn.aggregate_mean << " capped " << rn.aggregate_capped << " median " << rn.aggregate_median
               << " focus " << rn.crlb_inv_depth[1][1].item<double>());
  CHECK(rn.aggregate.item<double>() == Approx(rn.aggregate_capped));
  CHECK(rn.crlb_inv_depth[1][1].item<double>() > 1e4 * rn.crlb_inv_depth[0][0].item<double>());  // the focus (measured 6.4e6 1/m)
  CHECK(rn.aggregate_mean > 1e3 * rn.aggregate_capped);   // measured 215,204 against 1.32
  CHECK(rn.aggregate_capped <= (8 * 1.5 + s.aggregate_cap) / 9);  // eight ordinary points (each < 1.5) and one at the cap
  CHECK(rn.aggregate_median < 1.5);
  CHECK(rn.condition.sizes() == torch::IntArrayRef({3, 3}));
  // Bad settings are refused naming the key.
  optics::FisherSettings bad = s;
  bad.aggregate_cap = 0.0;
  CHECK_THROWS_WITH(optics::crlb_report(g, material, fresnel, bad), Catch::Contains("fisher.aggregate_cap"));
}
