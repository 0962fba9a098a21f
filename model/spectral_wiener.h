// The spectral Wiener cube: the linear minimum-mean-square-error (LMMSE)
// estimate of the hyperspectral cube x from the RGB sensor image y, with the
// image formation of the paper's Eq. 2 for one depth layer z,
//   Y_c(f) = Σ_λ Ω_c,λ K_λ,z(f) X_λ(f) + N_c(f)        (K: OTF, K(0) = 1),
// written per spatial frequency f as Y = H_z X + N, H_z [3, L]. The prior is
// a stationary Gaussian scene, separable in space and spectrum:
//   E[x] = μ (one spectrum for every pixel),  E[X Xᴴ](f) = S(f) Σ,
// Σ [L, L] the covariance of the scene's spectra (measured on the training
// split, data/spectral_moments.h), S(f) ∝ (|f| + f₀)^−α the natural images'
// power law (α = 2, mean 1 over f ≠ 0, f₀ one cycle per FFT side; the DC term
// ×10⁴, so the mean spectrum follows the image), and white noise of
// variance σ² per pixel. The depth is unknown: z is uniform over the K layers,
// and the estimator is the LMMSE one over that mixture,
//   X̂(f) = S Σ H̄ᴴ (S · E_z[H_z Σ H_zᴴ] + σ² I)⁻¹ (Y − Ω μ δ_f0),  H̄ = E_z[H_z],
// one 3×3 Hermitian solve per frequency, then x̂ = μ + F⁻¹ X̂. A band's
// detail where its own channel's OTF is lost (the chromatic blur of the outer
// bands) comes back from the channels that keep it, in proportion to the
// bands' covariance: the spectral prior does the work a per-channel Wiener
// filter (wiener_preinverse.h) cannot. A classical baseline, and the cube
// head's residual base with model.residual = "spectral_wiener".
// Borders as in wiener_preinverse.h (edge replication to an FFT-friendly size
// at least H + P − 1). The filter is computed and applied in float64 (the
// solves and the DC weight span many decades); the cube returns to the
// image's precision before the inverse FFT. Differentiable in the image and
// the PSFs, not in Ω or the prior.
#pragma once
#include <array>

#include <torch/types.h>

namespace hsd::model {

struct SpectralPrior {
  torch::Tensor mean;        // μ [L], radiance
  torch::Tensor covariance;  // Σ [L, L], symmetric positive semi-definite
  double noise_var = 0;      // σ² per pixel, in the image's units (> 0)
  double psd_exponent = 2.0; // α of S(f)
};

// Σ's eigen-directions that carry variance: Σ = U diag(e) Uᵀ with the
// eigenvalues at rounding level (below 1e-14 of the largest, and the negative
// ones rounding makes) dropped. covariance [L, L] -> e [R], U [L, R], float64.
// No gradient. The cut every user of the spectral prior shares.
struct SpectralDirections {
  torch::Tensor e, U;
};
SpectralDirections spectral_directions(const torch::Tensor& covariance);

// A field of 3×3 Hermitian matrices, one per spatial frequency: the real
// diagonal m00, m11, m22 [F] (float64) and the complex upper triangle m01,
// m02, m12 [F] (complex128; m10 = conj(m01), ...). Inverted by cofactors,
// elementwise over the frequencies (a batched LAPACK solve of 3×3 systems is
// ~10× slower): adj(M) (its real diagonal c00, c11, c22 and upper triangle
// c01, c02, c12) and 1/det M. Differentiable. M must be positive definite
// (the noise term makes every M here so); no check.
struct Hermitian3 {
  torch::Tensor m00, m11, m22, m01, m02, m12;
};
struct Hermitian3Inverse {
  torch::Tensor c00, c11, c22, c01, c02, c12, inv_det;
  // M⁻¹ r for r = (r0, r1, r2), each [..., F] broadcasting against [F].
  std::array<torch::Tensor, 3> solve(const torch::Tensor& r0, const torch::Tensor& r1, const torch::Tensor& r2) const;
};
Hermitian3Inverse hermitian3_inverse(const Hermitian3& m);

// Σ = V Vᵀ from Σ's eigen-decomposition (eigenvalues below 1e-14 of the
// largest dropped: R columns), as the rows Ω_cλ V_λj: omega [3, L], covariance
// [L, L] -> [3R, L] float64, rows ordered (c, j). No gradient.
torch::Tensor spectral_wiener_factor(const torch::Tensor& omega, const torch::Tensor& covariance);

// Throws InputError, naming `who`, unless image is [B, 3, H, W], psf
// [L, K, P, P] with P odd, omega [3, L], and the prior has a mean [L], a
// covariance [L, L] and a noise variance > 0: the inputs every user of the
// spectral prior (this cube, the spectral depth-from-defocus reader) takes.
void check_spectral_inputs(const char* who, const torch::Tensor& image, const torch::Tensor& psf,
                           const torch::Tensor& omega, const SpectralPrior& prior);

// image [B, 3, H, W], psf [L, K, P, P] (P odd, each summing to ≤ 1), omega
// [3, L] (the camera response that made the image), prior -> [B, L, H, W].
// = apply_spectral_wiener(spectral_wiener_filter(spectral_otf(psf, H, W),
// omega, prior), image): the parts below, for callers that apply one filter
// to many images (HsdNet keeps them while its PSFs and prior stay the same).
torch::Tensor spectral_wiener_cube(const torch::Tensor& image, const torch::Tensor& psf, const torch::Tensor& omega,
                                   const SpectralPrior& prior);

// The OTFs of psf [L, K, P, P] on the FFT grid of an H × W image extended by
// P/2 on every side (nh × nw, fast sizes): Kf [L, K, nh·(nw/2+1)] and their
// mean over the layers Kbar [L, nh·(nw/2+1)], complex128. Depends on the PSFs
// and the image's size only; differentiable in the PSFs.
struct SpectralOtf {
  int64_t H = 0, W = 0, r = 0, nh = 0, nw = 0;
  torch::Tensor Kf, Kbar;
};
SpectralOtf spectral_otf(const torch::Tensor& psf, int64_t H, int64_t W);

// Everything of the estimator but the image: Ω, μ, Σ (float64), S(f) and the
// inverse of M = S·E_z[H_z Σ H_zᴴ] + σ² I per frequency (flattened
// [nh·(nw/2+1)]). Differentiable in the PSFs through otf.
struct SpectralWienerFilter {
  SpectralOtf otf;  // its Kbar and sizes (Kf is not kept)
  torch::Tensor Om, mu, Sig, S;
  Hermitian3Inverse Minv;
};
// otf of L bands, omega [3, L], the prior of L bands (InputError otherwise).
SpectralWienerFilter spectral_wiener_filter(const SpectralOtf& otf, const torch::Tensor& omega, const SpectralPrior& prior);
// image [B, 3, H, W] of the filter's size -> the cube [B, L, H, W] in the
// image's precision (float64 for float64 images, float32 otherwise).
torch::Tensor apply_spectral_wiener(const SpectralWienerFilter& filter, const torch::Tensor& image);

// The part of a cube correction δ that the image does not determine:
//   (I − W H̄) δ,   W = S Σ H̄ᴴ (S · E_z[H_z Σ H_zᴴ] + σ² I)⁻¹,  H̄ = Ω diag(K̄),
// the filter's estimator W applied to the image H̄ δ the correction would
// make, taken off it. Where the image carries a band's frequency (K̄ large
// against the noise) W H̄ returns δ's observed colours and they are removed;
// where the blur or Ω's three channels lose it (δ in Ω's null space, or K̄ ≈ 0)
// δ passes. A residual added to the spectral Wiener cube through it cannot
// move what the image already fixed (model.project_residual). δ [B, L, H, W]
// of the filter's size, zero beyond it (zero-padded, not edge-replicated) ->
// [B, L, H, W] in δ's precision (float64 for float64, float32 otherwise);
// computed in float64. Linear in δ and differentiable in it and the PSFs.
torch::Tensor spectral_wiener_unobserved(const SpectralWienerFilter& filter, const torch::Tensor& delta);

// The prior's spatial power spectrum S(f) on the real half of an nh × nw DFT
// grid, flattened [nh·(nw/2+1)], float64: (|f| + 1/max(nh, nw))^−α, mean 1
// over f ≠ 0, the DC term ×10⁴.
torch::Tensor spectral_wiener_psd(int64_t nh, int64_t nw, double exponent, const torch::Device& device = torch::kCPU);

// σ² of the sensor model (optics/sensor_noise.h) averaged over its draws, at
// the mean image level y_mean: E[σ_read²] + y_mean / photons (read σ uniform
// on [std_min, std_max], or fixed at std_max when std_min < 0; photons 0 = no
// shot noise); floored at 1e-8 so the filter stays defined without noise.
double mean_noise_variance(double std_min, double std_max, double photons_at_saturation, double y_mean);

}  // namespace hsd::model
