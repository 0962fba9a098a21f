// The camera end to end: height map -> PSFs of the depth layers a scene
// occupies -> layered image formation (sensor_image.h) -> noise and read-out
// (sensor_noise.h). A thin stateful layer over the functional pieces, built
// from the config's sensor section. Leaves out what a scene does not need:
// PSFs and convolutions of empty layers, bands the camera does not see.
#pragma once
#include <functional>
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "optics/leave_out.h"
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

struct SensorImage {
  torch::Tensor image;          // [B, 3, H, W] after noise and read-out
  torch::Tensor clean;          // [B, 3, H, W] before noise
  torch::Tensor psf;            // [L, Z', P', P'] PSFs of the occupied layers (zero for bands left out; P' ≤ P if cropped)
  std::vector<int64_t> layers;  // indices into spec.depths_m of those layers
  std::vector<int64_t> bands;   // bands computed (the others were left out)
};

// Where the PSFs come from: PSFs [bands, layers, P, P] of the height map
// height_m [N, N] for those band and layer indices (either list may be
// empty). Default: PsfSimulator::compute. Data-parallel training passes one
// that shares the work among ranks (train/shared_psf.h); such a provider is
// then called exactly once per simulate_sensor call, even when nothing needs
// a PSF (empty lists), so every rank takes part in its collectives.
using PsfProvider = std::function<torch::Tensor(const torch::Tensor& height_m, const std::vector<int64_t>& layers,
                                                const std::vector<int64_t>& bands)>;

// radiance [B, L, H, W] (scene radiance per band), depth_m [B, 1, H, W] metres
// (finite, > 0), height_m [N, N] (may require grad). Differentiable in height_m
// and radiance.
SensorImage simulate_sensor(const PsfSimulator& psf_sim, const SensorModel& model, const torch::Tensor& height_m,
                            const torch::Tensor& radiance, const torch::Tensor& depth_m,
                            const NoiseRng& noise_rng = {}, const LeaveOut& leave = LeaveOut(),
                            const PsfProvider& psf_provider = nullptr);

}  // namespace hsd::optics
