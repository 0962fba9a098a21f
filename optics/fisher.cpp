#include "optics/fisher.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <torch/torch.h>

#include "common/error.h"
#include "optics/aperture.h"
#include "optics/pixel_quadrature.h"

namespace hsd::optics {

FisherGeometry make_fisher_geometry(const PsfSpec& spec, int64_t window_px, int64_t nodes) {
  if (window_px < 3 || window_px % 2 == 0) throw InputError("config key fisher.window_px: must be odd and >= 3");
  if (nodes < 1 || nodes > 8) throw InputError("config key fisher.pixel_nodes: must be in [1, 8]");
  FisherGeometry g;
  g.sensor_distance_m = spec.sensor_distance_m, g.pixel_pitch_m = spec.pixel_pitch_m, g.doe_pitch_m = spec.doe_pitch_m;
  g.aperture_diameter_m = spec.aperture_diameter_m;
  g.doe_samples = spec.doe_samples, g.window_px = window_px, g.nodes = nodes;
  g.aperture = aperture_transmission(spec.doe_samples, spec.doe_pitch_m, spec.aperture_diameter_m, spec.aperture_shape)
                   .to(torch::kFloat64);
  g.aperture_energy = g.aperture.pow(2).sum().item<double>();
  if (!(g.aperture_energy > 0)) throw InputError("Fisher information: the aperture covers no DOE sample");
  g.pupil_x = centred_coordinates(spec.doe_samples, spec.doe_pitch_m).to(torch::kFloat64);
  const Quadrature1D q = gauss_legendre(nodes);
  const torch::Tensor px = centred_coordinates(window_px, spec.pixel_pitch_m).to(torch::kFloat64);
  const torch::Tensor nd = torch::tensor(q.nodes, torch::kFloat64) * spec.pixel_pitch_m;
  g.sensor_x = (px.view({-1, 1}) + nd.view({1, -1})).reshape(-1);
  g.weights = torch::tensor(q.weights, torch::kFloat64);
  return g;
}

torch::Tensor point_psf(const FisherGeometry& g, const torch::Tensor& height_m, const torch::Tensor& inv_depth,
                        const torch::Tensor& wavelength_nm, double eta0, double deta_dnm, const torch::Tensor& shift_x_px,
                        const torch::Tensor& shift_y_px) {
  const double lam0_nm = wavelength_nm.item<double>();
  const torch::Tensor lam = wavelength_nm * 1e-9;                     // metres
  const torch::Tensor eta = eta0 + (wavelength_nm - lam0_nm) * deta_dnm;  // linearised dispersion
  const double s = g.sensor_distance_m;
  // Pupil field M = A exp(i 2π (η − 1) h / λ)
  const torch::Tensor field = torch::polar(g.aperture, (2.0 * M_PI) * (eta - 1.0) / lam * height_m);
  // Separable kernel K[m, j] = exp(i(−2π x_m ξ_j/(λ s) + π ξ_j² (D + 1/s)/λ)); a
  // shift of the PSF by Δ moves every sensor node to x_m − Δ. Rows (y) on the
  // left of the field [y, x], columns (x) on the right.
  const torch::Tensor xi = g.pupil_x.view({1, -1});
  auto kernel = [&](const torch::Tensor& shift_px) {
    torch::Tensor xm = g.sensor_x.view({-1, 1});
    if (shift_px.defined()) xm = xm - shift_px * g.pixel_pitch_m;
    const torch::Tensor phase = (-2.0 * M_PI / s) * (xm * xi) / lam + M_PI * xi.pow(2) * (inv_depth + 1.0 / s) / lam;
    return torch::polar(torch::ones_like(phase), phase);  // [P·n, N]
  };
  const torch::Tensor Ky = kernel(shift_y_px);
  const torch::Tensor Kx = shift_x_px.defined() || shift_y_px.defined() ? kernel(shift_x_px) : Ky;
  const torch::Tensor F = torch::mm(torch::mm(Ky, field), Kx.t());  // [P·n, P·n]
  const torch::Tensor re = torch::real(F), im = torch::imag(F);
  const torch::Tensor I = re * re + im * im;
  const int64_t P = g.window_px, n = g.nodes;
  const torch::Tensor W = torch::outer(g.weights, g.weights).view({1, n, 1, n});
  const torch::Tensor pix = (I.view({P, n, P, n}) * W).sum({1, 3});
  // Fraction of the light through the aperture that lands in each pixel
  // (Parseval, as psf.cpp's energy_in_window): light leaving the window is lost,
  // so a design cannot buy information by spreading the PSF beyond it.
  const torch::Tensor scale = (g.pixel_pitch_m * g.doe_pitch_m / s) * (g.pixel_pitch_m * g.doe_pitch_m / s) / (lam * lam);
  return pix * scale / g.aperture_energy;
}

torch::Tensor fisher_from_jacobian(const torch::Tensor& mu, const std::vector<torch::Tensor>& dmu, double background) {
  if (background < 0) throw InputError("Fisher information: background must be >= 0");
  const torch::Tensor den = (mu + background).clamp_min(1e-12);  // μ + b > 0 always
  const int64_t K = int64_t(dmu.size());
  std::vector<torch::Tensor> rows;
  for (int64_t i = 0; i < K; ++i) {
    std::vector<torch::Tensor> row;
    for (int64_t j = 0; j < K; ++j) row.push_back((dmu[size_t(i)] * dmu[size_t(j)] / den).sum());
    rows.push_back(torch::stack(row));
  }
  return torch::stack(rows);
}

std::vector<torch::Tensor> jacobian_by_autograd(const torch::Tensor& mu, const std::vector<torch::Tensor>& params,
                                                bool create_graph) {
  // g(u) = ∂/∂θ Σ u ⊙ μ = Jᵀ u is linear in u; ∂g_k/∂u = ∂μ/∂θ_k.
  const torch::Tensor u = torch::zeros_like(mu).requires_grad_(true);
  const auto g = torch::autograd::grad({(u * mu).sum()}, params, {}, /*retain_graph=*/true, /*create_graph=*/true);
  std::vector<torch::Tensor> J;
  for (size_t k = 0; k < params.size(); ++k)
    J.push_back(torch::autograd::grad({g[k]}, {u}, {}, /*retain_graph=*/true, create_graph)[0]);
  return J;
}

Crlb crlb_from_fisher(const torch::Tensor& fisher) {
  Crlb c;
  c.fisher = fisher;
  const int64_t K = fisher.size(0);
  const torch::Tensor sym = 0.5 * (fisher + fisher.t());
  const torch::Tensor ev = torch::linalg_eigvalsh(sym.detach());
  const double lo = ev.min().item<double>(), hi = ev.max().item<double>();
  c.condition = lo > 0 ? hi / lo : std::numeric_limits<double>::infinity();
  const torch::Tensor ridge = 1e-12 * sym.diagonal().sum().detach().clamp_min(1e-300) * torch::eye(K, fisher.options());
  const torch::Tensor inv = torch::linalg_inv(sym + ridge);
  c.crlb = inv.diagonal().clamp_min(0.0).sqrt();
  return c;
}

Crlb crlb_with_nuisance(const torch::Tensor& fisher, int64_t n_interest) {
  const int64_t K = fisher.size(0);
  if (n_interest < 1 || n_interest > K) throw InputError("Fisher information: n_interest must be in [1, K]");
  if (n_interest == K) return crlb_from_fisher(fisher);
  using torch::indexing::Slice;
  const torch::Tensor sym = 0.5 * (fisher + fisher.t());
  const torch::Tensor A = sym.index({Slice(0, n_interest), Slice(0, n_interest)});
  const torch::Tensor B = sym.index({Slice(0, n_interest), Slice(n_interest, K)});
  const torch::Tensor C = sym.index({Slice(n_interest, K), Slice(n_interest, K)});
  const int64_t m = K - n_interest;
  const torch::Tensor ridge = 1e-12 * C.diagonal().sum().detach().clamp_min(1e-300) * torch::eye(m, fisher.options());
  const torch::Tensor schur = A - torch::mm(B, torch::linalg_solve(C + ridge, B.t()));
  return crlb_from_fisher(schur);
}

void check_aggregate(const FisherSettings& s) {
  if (!(s.aggregate_cap > 0)) throw InputError("config key fisher.aggregate_cap: must be > 0");
}

void set_aggregates(CrlbReport& r, const torch::Tensor& t, const FisherSettings& s) {
  const torch::Tensor mean = t.mean(), capped = t.clamp_max(s.aggregate_cap).mean();
  const torch::Tensor median = std::get<0>(t.view(-1).sort()).select(0, (t.numel() - 1) / 2);  // lower median
  r.aggregate_mean = mean.item<double>();
  r.aggregate_capped = capped.item<double>();
  r.aggregate_median = median.item<double>();
  r.aggregate = s.aggregate == CrlbAggregate::mean ? mean : s.aggregate == CrlbAggregate::median ? median : capped;
}

CrlbReport crlb_report(const FisherGeometry& g, const Material& material, const torch::Tensor& height_m,
                       const FisherSettings& s) {
  check_aggregate(s);
  auto has = [&](NuisanceParam n) { return std::find(s.nuisance.begin(), s.nuisance.end(), n) != s.nuisance.end(); };
  CrlbReport r;
  r.wavelengths_nm = s.wavelengths_nm;
  r.nuisance = s.nuisance;
  for (double z : s.depths_m) r.inv_depths.push_back(1.0 / z);
  const int64_t L = int64_t(s.wavelengths_nm.size()), Z = int64_t(s.depths_m.size());
  std::vector<torch::Tensor> cd, cl, terms;
  std::vector<double> cond;
  const bool design = height_m.requires_grad();
  for (int64_t l = 0; l < L; ++l) {
    const double w = s.wavelengths_nm[size_t(l)];
    const double eta0 = material.index(w * 1e-9);
    const double deta = (material.index((w + 0.5) * 1e-9) - material.index((w - 0.5) * 1e-9));  // per nm
    for (int64_t zi = 0; zi < Z; ++zi) {
      const torch::Tensor D = torch::tensor(r.inv_depths[size_t(zi)], torch::kFloat64).requires_grad_(true);
      const torch::Tensor lam = torch::tensor(w, torch::kFloat64).requires_grad_(true);
      std::vector<torch::Tensor> params{D, lam};
      torch::Tensor sx, sy, a;
      // In the order of s.nuisance (their order does not change the bound of (D, λ)).
      for (const auto& n : s.nuisance) {
        torch::Tensor p = torch::zeros({}, torch::kFloat64);
        if (n == NuisanceParam::N) p = torch::ones({}, torch::kFloat64);
        p.requires_grad_(true);
        (n == NuisanceParam::x ? sx : n == NuisanceParam::y ? sy : a) = p;
        params.push_back(p);
      }
      torch::Tensor mu = s.photons * point_psf(g, height_m, D, lam, eta0, deta, has(NuisanceParam::x) ? sx : torch::Tensor(),
                                               has(NuisanceParam::y) ? sy : torch::Tensor());
      if (has(NuisanceParam::N)) mu = mu * a;
      const auto J = jacobian_by_autograd(mu, params, design);
      const Crlb c = crlb_with_nuisance(fisher_from_jacobian(mu, J, s.background), 2);
      r.max_condition = std::max(r.max_condition, c.condition);
      cond.push_back(c.condition);
      cd.push_back(c.crlb[0]);
      cl.push_back(c.crlb[1]);
      const torch::Tensor u = c.crlb[0] / s.inv_depth_spacing, v = c.crlb[1] / s.band_width_nm;
      terms.push_back(((u * u + v * v) * 0.5).sqrt());
    }
  }
  set_aggregates(r, torch::stack(terms), s);
  r.crlb_inv_depth = torch::stack(cd).detach().view({L, Z});
  r.crlb_wavelength_nm = torch::stack(cl).detach().view({L, Z});
  r.condition = torch::tensor(cond, torch::kFloat64).view({L, Z});
  return r;
}

}  // namespace hsd::optics
