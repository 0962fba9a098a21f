#include "optics/off_axis_psf.h"

#include <algorithm>
#include <cmath>

#include <torch/torch.h>

#include "common/error.h"
#include "optics/aperture.h"
#include "optics/fresnel_mft.h"
#include "optics/pixel_quadrature.h"

namespace hsd::optics {

double off_axis_neglected_phase_rad(const PsfSpec& s, double th) {
  const double a = 0.5 * s.aperture_diameter_m, R0 = s.sensor_distance_m / std::cos(th);
  const double lmin = *std::min_element(s.wavelengths_m.begin(), s.wavelengths_m.end());
  return 2.0 * M_PI / lmin * a * a * a * std::abs(std::sin(th)) / (2.0 * R0 * R0);
}

torch::Tensor off_axis_psf(const PsfSpec& s, const torch::Tensor& height_m, double th) {
  if (!(std::abs(th) < M_PI / 6)) throw InputError("off_axis_psf: field angle must be below 30 degrees");
  torch::NoGradGuard no_grad;
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
  const int64_t N = s.doe_samples, P = s.psf_size, L = int64_t(s.wavelengths_m.size()), Z = int64_t(s.depths_m.size());
  const torch::Tensor xs = centred_coordinates(N, s.doe_pitch_m).to(f64);  // pupil coordinates [N]
  const torch::Tensor A = aperture_transmission(N, s.doe_pitch_m, s.aperture_diameter_m, s.aperture_shape).to(f64);
  const torch::Tensor h = height_m.detach().to(torch::kFloat64).cpu();
  const torch::Tensor pix = centred_coordinates(P, s.pixel_pitch_m).to(f64);
  const double c = std::cos(th), sn = std::sin(th), R0 = s.sensor_distance_m / c;
  const std::vector<double> lam = s.spectral_wavelengths_m(), wts = s.spectral_weights();
  const int64_t K = s.spectral_samples;
  const torch::Tensor X = xs.view({1, -1}), Y = xs.view({-1, 1});  // M[y, x]: rows y, columns x
  torch::Tensor out = torch::zeros({L, Z, P, P}, f64);
  for (int64_t l = 0; l < L; ++l) {
    const Quadrature1D q = gauss_legendre(s.pixel_nodes[size_t(l)]);
    const int64_t n = int64_t(q.nodes.size());
    const torch::Tensor sensor = (pix.view({-1, 1}) + torch::tensor(q.nodes, f64).view({1, -1}) * s.pixel_pitch_m).reshape(-1);  // [P·n]
    const torch::Tensor w = torch::tensor(q.weights, f64);
    const torch::Tensor w2 = (w.view({-1, 1}) * w.view({1, -1}));  // [n, n]
    for (int64_t k = 0; k < K; ++k) {
      const size_t j = size_t(l * K + k);
      const double lambda = lam[j], kw = 2.0 * M_PI / lambda;
      const double eta = s.spectral_refractive_index.empty() ? s.refractive_index[size_t(l)] : s.spectral_refractive_index[j];
      const torch::Tensor M = compute_pupil_field(A, h, lambda, eta, torch::kComplexDouble);  // [N, N]
      // Output-side linear phases (the tilt kernels), float64 phases wrapped before the phasor.
      const torch::Tensor tx = -kw * c * c / R0 * sensor.view({-1, 1}) * xs.view({1, -1});  // [P·n, N]
      const torch::Tensor ty = -kw / R0 * sensor.view({-1, 1}) * xs.view({1, -1});
      for (int64_t zi = 0; zi < Z; ++zi) {
        const double z = s.depths_m[size_t(zi)], r0 = z / c, x0 = z * std::tan(th);
        const double curv = 1.0 / r0 + 1.0 / R0;
        const torch::Tensor Kx = phasor(tx + (0.5 * kw * c * c * curv) * xs.pow(2).view({1, -1}), torch::kComplexDouble);
        const torch::Tensor Ky = phasor(ty + (0.5 * kw * curv) * xs.pow(2).view({1, -1}), torch::kComplexDouble);
        // ψ: the exact spherical phase minus its linear and quadratic parts about the chief ray.
        const torch::Tensor rr = torch::sqrt((X - x0).pow(2) + Y.pow(2) + z * z);
        const torch::Tensor dr = (X.pow(2) - 2.0 * X * x0 + Y.pow(2)) / (rr + r0);  // r − r0
        const torch::Tensor psi = kw * (dr + X * sn - (X.pow(2) * c * c + Y.pow(2)) / (2.0 * r0));
        const torch::Tensor field = M * phasor(psi, torch::kComplexDouble);
        const torch::Tensor F = torch::mm(torch::mm(Ky, field), Kx.transpose(0, 1));  // [P·n (v), P·n (Δu)]
        const torch::Tensor I = (torch::real(F).pow(2) + torch::imag(F).pow(2)).view({P, n, P, n});
        const torch::Tensor pixel = (I * w2.view({1, n, 1, n})).sum({1, 3});  // [P, P]
        // Light per pixel ∝ |F|² / λ² (the Fresnel integral's 1/(λR) factor; the other factors are the same
        // for a band's nodes), so the band's wavelengths mix as the on-axis simulator mixes them.
        out[l][zi] += (wts[j] / (lambda * lambda)) * pixel;
      }
    }
  }
  return out / out.sum({2, 3}, true).clamp_min(1e-300);
}

}  // namespace hsd::optics
