// The spectral Wiener cube with an edge prior: the cube x that minimises
//   E(x) = ½ (y − H̄ x)ᴴ N⁻¹ (y − H̄ x) + ½ (x − μ)ᵀ C⁻¹ (x − μ) + (λ/σ²) Σ_p ‖∇x(p)‖,
// the first two terms those whose minimiser is the spectral Wiener cube
// (spectral_wiener.h: the image formation of the paper's Eq. 2 with the
// layer unknown, N below; the Gaussian prior C = S(f) Σ of the training
// spectra), the third a total variation
// coupled across the bands: ‖∇x(p)‖ is the norm of all L bands' forward
// differences in x and y at pixel p, so the bands share their edges. A
// linear estimate must blur a step it cannot resolve; this prior lets the
// cube keep steps where the data show them (a piecewise-smooth scene).
//
// Solved by half-quadratic splitting (Geman & Yang 1995; Krishnan & Fergus
// 2009): with an auxiliary gradient field v [L, 2] per pixel,
//   v ← shrink(∇x, λ/ρ̃)   (the group soft threshold: ∇x · max(0, 1 − t/‖∇x‖)),
//   x ← the LMMSE cube under the prior made sharper by ½ (ρ̃/σ²) ‖∇x − v‖²,
// for ρ̃ = rho_start · rho_factor^k, k = 0 … iterations − 1, starting from the
// spectral Wiener cube (ρ̃ = 0). The x-step is exact per spatial frequency:
// in Σ = U diag(e) Uᵀ the added term is isotropic in the bands, so the
// prior's covariance stays diagonal in U,
//   C'(f) = U diag(c_j(f)) Uᵀ,  c_j = S e_j / (1 + ρ |D(f)|² S e_j),  ρ = ρ̃/σ²,
// |D(f)|² = 4 sin²(π f_y) + 4 sin²(π f_x) (f in cycles per pixel), the prior's
// mean moves to m = ρ C' Dᴴ V, and
//   X̂ = m + C' H̄ᴴ M⁻¹ (Y − H̄ m),  M = Σ_j c_j T̄_j + N,  T̄_j = (H̄ u_j)(H̄ u_j)ᴴ,
// one 3×3 Hermitian solve per frequency as in spectral_wiener.h. The unknown
// layer enters as the linear model Y = H̄ X + E with E uncorrelated with X and
//   N = Cov(E) = S (E_z[H_z Σ H_zᴴ] − H̄ Σ H̄ᴴ) + σ² I,
// which has the mixture's first and second moments, so ρ = 0 is the spectral
// Wiener cube, every x-step is the exact minimiser of one quadratic energy,
// and a vanishing λ keeps the Wiener cube as the splitting's fixed point.
//
// λ (`weight`) is in the image's units (a gradient norm of radiance: a step
// smaller than about λ/ρ̃ is smoothed at the end); ρ̃ is relative to the
// data's precision 1/σ². Borders as in spectral_wiener.h: the cube is
// solved on the FFT grid of the edge-replicated image (periodic there) and
// cropped. Float64 inside; no gradient (an evaluation-time estimator).
#pragma once
#include <torch/types.h>

#include "model/spectral_wiener.h"

namespace hsd::model {

struct EdgePriorSettings {
  double weight = 0.0;       // λ [radiance]; 0 = the spectral Wiener cube
  int64_t iterations = 8;    // splitting steps (≥ 1 when weight > 0)
  double rho_start = 1e-3;   // ρ̃ of the first step, relative to 1/σ²
  double rho_factor = 2.0;   // ρ̃'s growth per step (> 1)
};

// image [B, 3, H, W] of otf's size, otf with its per-layer OTFs (otf.Kf
// [L, K, F], from spectral_otf), omega [3, L], prior of L bands ->
// [B, L, H, W] in the image's precision (float64 for float64 images, float32
// otherwise). InputError on any other shape or a setting out of range.
torch::Tensor spectral_tv_cube(const torch::Tensor& image, const SpectralOtf& otf, const torch::Tensor& omega,
                               const SpectralPrior& prior, const EdgePriorSettings& settings);

// Σ_p ‖∇x(p)‖ over the interior of x [B, L, H, W] per image [B] (forward
// differences, the bands' norm): the edge prior's term, for tests and logs.
torch::Tensor coupled_total_variation(const torch::Tensor& x);

}  // namespace hsd::model
