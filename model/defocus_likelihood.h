// Classical depth from defocus: the local likelihood of each depth layer's
// PSF given the sensor image, a cost volume a reader (or a network) can take
// the depth from without learning to compare blurs.
//
// Image model (the same as optics/depth_distinctness.h's scene cue): in colour
// channel c a region at layer k is y_c = h_k,c ∗ x_c + n, with x_c a stationary
// Gaussian texture of power spectrum s·S(f), S(f) ∝ 1/(|f|² + f₀²) (mean 1
// over the frequencies, f in cycles per pixel), n white noise of variance
// s·ρ, h_k,c the camera's RGB PSF of the layer (model::camera_rgb_psfs). Then
// the image's DFT Y_c(f) is Gaussian with variance s·D_k,c(f),
//   D_k,c(f) = S(f)|H_k,c(f)|² + ρ,
// and the negative log-likelihood per pixel of n pixels, with the unknown
// texture scale s set to its maximum-likelihood value (a region's contrast
// says nothing about its depth), is, up to a constant,
//   ℓ_k = Σ_c [ log( (1/n) Σ_x |w_k,c(x)|² ) + mean_f log D_k,c(f) ],
//   w_k,c = F⁻¹[ Y_c / √D_k,c ]   (the image whitened under layer k's model).
// Localised: the mean of |w|² over a window_px × window_px box around each
// pixel (Parseval's identity over the box, approximately). The layer of least
// ℓ_k is the maximum-likelihood depth layer at that pixel.
// Borders: the image is extended by edge replication to an FFT-friendly size
// at least H + P − 1, as in wiener_preinverse.h.
#pragma once
#include <vector>

#include <torch/types.h>

#include "model/spectral_wiener.h"

namespace hsd::model {

struct DefocusModel {
  double noise_ratio = 0.1;            // ρ: noise variance relative to the texture's (> 0)
  double corner_cycles_per_px = 1.0 / 64;  // f₀ of the texture spectrum (> 0)
  int64_t window_px = 15;              // the box the likelihood is pooled over (odd, >= 1)
};

// image [B, C, H, W] (linear sensor values), rgb_psf [K, C, P, P] (P odd,
// each slice summing to 1) -> ℓ [B, K, H, W] in nats per pixel (smaller =
// more likely), float32 (float64 inputs stay float64). Differentiable in the
// image and the PSFs.
torch::Tensor defocus_cost_volume(const torch::Tensor& image, const torch::Tensor& rgb_psf, const DefocusModel& m);

// The same reader with the spectral prior of the spectral Wiener cube
// (spectral_wiener.h) in place of a grey texture per channel: under layer k
// the image's DFT is Gaussian with the 3×3 covariance per frequency
//   M_k(f) = S(f) H_k(f) Σ H_k(f)ᴴ + σ² I,   H_k = Ω diag(K_λ,k(f)) [3, L],
// (the camera response Ω, the band OTFs K, the training radiance's spectral
// covariance Σ and mean μ, S the prior's 1/f^α spectrum, σ² its noise), so
// colour and depth are read together: a surface's spectrum moves each
// channel's blur (a diffractive lens focuses by wavelength) and the prior says
// how. With w_k = F⁻¹[L_k⁻¹ (Y − Ω μ δ_f0)] (M_k = L_k L_kᴴ, Cholesky) and one contrast scale profiled
// out over the box,
//   ℓ_k = 3 log( (1/3n) Σ_x Σ_c |w_k,c(x)|² ) + mean_f log det M_k(f).
// image [B, 3, H, W], psf [L, K, P, P] (band PSFs, P odd), omega [3, L],
// window_px odd -> ℓ [B, K, H, W], float32 (float64 in for float64 out).
// Differentiable in the image alone: the PSFs, the camera and the prior enter
// as constants (detached), so no gradient reaches them through the whitening
// or the log-determinant. A caller that wants none passes a detached image.
torch::Tensor spectral_defocus_cost_volume(const torch::Tensor& image, const torch::Tensor& psf, const torch::Tensor& omega,
                                           const SpectralPrior& prior, int64_t window_px);

// The maximum-likelihood layer per pixel: cost [B, K, H, W] -> depth [B, H, W]
// [m], each pixel at layer_depths_m[argmin_k ℓ_k] (size K). Where several
// layers tie for the least cost (within kLayerTieNats), the pixel is at the
// mean of their depths: a tie is no reading, and an index order would bias
// it (to the nearest layer, the first; a camera without a depth cue, the
// all-in-focus control, ties at every pixel).
inline constexpr double kLayerTieNats = 1e-6;  // [nats per pixel]; float32's resolution near 8
torch::Tensor defocus_layer_depth(const torch::Tensor& cost, const std::vector<double>& layer_depths_m);

}  // namespace hsd::model
