// Leaving out what a scene does not need (the user's "leave out what a given
// scene does not need"): the rules simulate_sensor applies and the two
// measurements they rest on. Every rule keeps the result equal to the full
// computation up to its stated bound (tests/optics/test_discretisation.cpp).
#pragma once
#include <vector>

#include <torch/types.h>

namespace hsd::optics {

// What simulate_sensor may leave out because the scene does not need it.
struct LeaveOut {
  bool layers = true;        // depth layers no pixel occupies: no PSFs, no convolutions (exact)
  bool bands = true;         // bands the camera does not see or the scene does not emit
  // Dark bands, darkest first, while for every image b and channel c
  //   Σ_{l dark} Ω_c,l · max_pixels I_b,l ≤ band_tol · Σ_l Ω_c,l · mean_pixels I_b,l:
  // since each PSF sums to at most 1 and the masks to 1, leaving them out moves
  // no pixel of image b, channel c by more than band_tol times that image's mean
  // signal in c. 0 = exact zeros only.
  double band_tol = 1e-7;
  // Without a gradient to the height map: crop the PSFs to the smallest odd
  // window whose outside holds at most psf_crop_tol of every (λ, z) PSF's light
  // (smaller convolutions). 0 = never crop.
  double psf_crop_tol = 1e-7;
  // Optional [B, 1, H, W] map (> 0.5 = a pixel that will be used): the image is
  // rendered only on the bounding box of the used pixels plus the reach of the
  // PSF and the mask blur, and is zero (plus noise) elsewhere. Used pixels are exact.
  torch::Tensor valid;
};

// Bands to compute: all but the dark ones of the LeaveOut rule (sorted).
// radiance [B, L, H, W], omega [C, L].
std::vector<int64_t> needed_bands(const torch::Tensor& radiance, const torch::Tensor& omega, double band_tol);

// Smallest odd window (≤ P) holding all but `tol` of the light of every PSF in
// psf [L, Z, P, P] (each summing to 1).
int64_t psf_support_window(const torch::Tensor& psf, double tol);

}  // namespace hsd::optics
