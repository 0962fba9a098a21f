// The camera end to end: height map -> PSFs of the depth layers a scene
// occupies -> layered image formation (sensor_image.h) -> noise and read-out
// (sensor_noise.h). A thin stateful layer over the functional pieces, built
// from the config's sensor section. Leaves out what a scene does not need:
// PSFs and convolutions of empty layers, bands the camera does not see.
#pragma once
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "optics/psf.h"
#include "optics/sensor_noise.h"

namespace hsd::optics {

struct SensorModel {
  torch::Tensor omega;          // camera response [3, L] (spectrum.h scaling)
  double mask_sigma_px = 1.0;   // Gaussian σ of the soft layer masks
  bool occlusion = false;       // Ikoma et al. compositing instead of the paper's linear model
  NoiseModel noise;
};

// From the config's sensor section and the PSF spec's bands.
SensorModel make_sensor_model(const SensorConfig& cfg, const PsfSpec& spec, double band_width_m);

// What simulate_sensor may leave out because the scene does not need it. Every
// rule keeps the result equal to the full computation up to its stated bound.
struct LeaveOut {
  bool layers = true;        // depth layers no pixel occupies: no PSFs, no convolutions (exact)
  bool bands = true;         // bands the camera does not see or the scene does not emit
  // A band l is dark when Σ_{dark} max_c Ω_c,l · max_pixels I_l ≤ band_tol · min_c Σ_l Ω_c,l mean I_l:
  // leaving the dark bands out changes no pixel by more than band_tol times the
  // image's mean signal. 0 = only bands that are exactly zero.
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

// Bands to compute: those with a response and emission above the LeaveOut rule
// (sorted). radiance [B, L, H, W], omega [3, L].
std::vector<int64_t> needed_bands(const torch::Tensor& radiance, const torch::Tensor& omega, double band_tol);

// Smallest odd window (≤ P) holding all but `tol` of the light of every PSF in
// psf [L, Z, P, P] (each summing to 1).
int64_t psf_support_window(const torch::Tensor& psf, double tol);

struct SensorImage {
  torch::Tensor image;          // [B, 3, H, W] after noise and read-out
  torch::Tensor clean;          // [B, 3, H, W] before noise
  torch::Tensor psf;            // [L, Z', P', P'] PSFs of the occupied layers (zero for bands left out; P' ≤ P if cropped)
  std::vector<int64_t> layers;  // indices into spec.depths_m of those layers
  std::vector<int64_t> bands;   // bands computed (the others were left out)
};

// radiance [B, L, H, W] (scene radiance per band), depth_m [B, 1, H, W] metres
// (finite, > 0), height_m [N, N] (may require grad). Differentiable in height_m
// and radiance.
SensorImage simulate_sensor(const PsfSimulator& psf_sim, const SensorModel& model, const torch::Tensor& height_m,
                            const torch::Tensor& radiance, const torch::Tensor& depth_m,
                            c10::optional<at::Generator> generator = c10::nullopt, const LeaveOut& leave = LeaveOut());

}  // namespace hsd::optics
