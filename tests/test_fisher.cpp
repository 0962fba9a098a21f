// Fisher information and CRLB: the textbook bound of a Gaussian spot whose
// width is the parameter (Poisson noise), autograd derivatives of the PSF
// against finite differences, Zernike orthonormality, a design that lowers
// the CRLB below its (Fresnel) start, and symmetric cases without NaN.
#include <catch2/catch.hpp>
#include <cmath>

#include "helpers.h"
#include "optics/doe.h"
#include "optics/fisher.h"
#include "optics/fisher_design.h"
#include "optics/zernike.h"

using namespace hsd;

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
  ff.basis = "freeform";
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
