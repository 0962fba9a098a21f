// The scene's light read from its sensor image: a posterior over the training
// illuminants (data.illuminants), and the spectral prior that follows from it.
//
// The spectral Wiener cube (spectral_wiener.h) uses the training radiance's
// moments, a mixture over the K illuminants with equal weights:
//   μ = E_k[μ_k],  Σ = E_k[M_k] − μ μᵀ,
//   μ_k = E[s] e_k ⊙ m_r,  M_k = E[s²] diag(e_k) R_r diag(e_k),
// m_r, R_r the reflectance's mean and second moment over the training pixels,
// e_k the k-th illuminant's band means, s ~ U[lo, hi] the global intensity
// (data/spectral_moments.h). One scene is lit by one illuminant, so its
// image says which: this reader replaces the equal weights with a posterior
// w_k ∝ p(image | k)^(1/T), and the prior becomes the mixture under w,
//   μ_w = Σ_k w_k μ_k,  Σ_w = Σ_k w_k M_k − μ_w μ_wᵀ,
// which is the equal-weight prior for w = 1/K. Equal weights are the LMMSE
// answer before the image is seen; the posterior mixture is that of the
// Gaussian-mixture prior after it (a non-linear estimate of the light, a
// linear one of the cube given the light).
//
// The likelihood is that of the image's block means b_j [3] (blocks of
// block_px²; they average the blur and the noise down): under illuminant k
// and intensity s, b_j = s G r_j + n_j with G = Ω diag(κ) (κ_λ the share of
// band λ's light the PSFs keep in their window, mean over the layers), r_j
// the block's lit reflectance drawn from N(e_k ⊙ m_r, diag(e_k) C_r diag(e_k)),
// C_r = R_r − m_r m_rᵀ, and n_j white of variance σ²/block_px² per channel
// plus a floor of 10⁻⁴ of the image's mean square (model error):
//   ℓ_k = max_s Σ_j log N(b_j; s G (e_k ⊙ m_r), s² G C_k Gᵀ + τ² I),
// the intensity profiled on a log grid over [lo/2, 2 hi] (the evaluation
// may light a scene outside the training range). The J blocks are not
// independent (textures and surfaces span several), so the log-likelihood
// is tempered: w = softmax(ℓ / T) with T = J / effective_blocks.
//
// Shapes and units: radiance and image in the sensor's linear units;
// everything float64 inside. No gradient (the light is read, not learned).
#pragma once
#include <torch/types.h>

#include "model/spectral_wiener.h"

namespace hsd::model {

// τ²'s floor, a share of the block means' mean square (the model's error).
inline constexpr double kIlluminantModelFloor = 1e-4;

// The profiled intensities: 49 points spaced evenly in log over
// [min/2, 2 max], float64 [49].
torch::Tensor illuminant_intensity_grid(double intensity_min, double intensity_max);

struct IlluminantMoments {
  torch::Tensor mean;    // [K, L] e_k ⊙ m_r, at unit intensity
  torch::Tensor second;  // [K, L, L] diag(e_k) R_r diag(e_k), at unit intensity
  double intensity_min = 1, intensity_max = 1;  // s ~ U[min, max] in training
};

struct IlluminantReaderSettings {
  int64_t block_px = 16;          // the block of the block means [px]
  double effective_blocks = 32;   // the tempering: ℓ counts as this many independent blocks (model.illuminant_effective_blocks)
};

// reflectance mean m_r [L] and second moment R_r [L, L], illuminants [K, L]
// (band means), intensity range -> the per-illuminant moments above.
IlluminantMoments illuminant_moments(const torch::Tensor& reflectance_mean, const torch::Tensor& reflectance_second,
                                     const torch::Tensor& illuminants, double intensity_min, double intensity_max);

// image [B, 3, H, W], omega [3, L], band_energy κ [L] (in (0, 1]), noise
// variance σ² (> 0) -> ℓ [B, K] float64, the profiled log-likelihood of each
// illuminant (up to a constant per image). InputError on bad shapes.
torch::Tensor illuminant_log_likelihood(const torch::Tensor& image, const torch::Tensor& omega,
                                        const torch::Tensor& band_energy, const IlluminantMoments& m, double noise_var,
                                        int64_t block_px);

// ℓ [B, K] -> w [B, K] = softmax(ℓ · effective_blocks / J), J the number of
// blocks of an H × W image.
torch::Tensor illuminant_posterior(const torch::Tensor& log_likelihood, int64_t H, int64_t W,
                                   const IlluminantReaderSettings& s);

// weights w [K] (summing to 1) -> the mixture prior (μ_w, Σ_w) above, float64,
// with the given noise variance.
SpectralPrior illuminant_mixture_prior(const IlluminantMoments& m, const torch::Tensor& weights, double noise_var);

}  // namespace hsd::model
