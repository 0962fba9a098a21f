// What one training step and one validation report (Trainer::step,
// Trainer::validate), and the phase timings of a profiled step.
#pragma once
#include <cmath>
#include <cstdint>

namespace hsd::train {

struct StepStats {
  double loss = 0, hs = 0, depth = 0, tv = 0, lr_net = 0, lr_doe = 0;
};

// Seconds per phase of Trainer::step, summed over `steps` steps (set_profile).
// CPU timings (a CUDA device would need a synchronisation per phase).
struct StepProfile {
  // inputs_forward: the network's linear inputs and base (the Wiener
  // pre-inversion, the spectral Wiener cube) from the rendered window;
  // network_forward: the U-Net and its heads. The inputs' backward is in
  // network_backward (the graph is cut at the rendered window).
  double psf_forward = 0, sensor_forward = 0, inputs_forward = 0, network_forward = 0, loss = 0;
  double network_backward = 0, sensor_backward = 0, psf_backward = 0, optimizer = 0;
  int64_t steps = 0;
};

struct ValStats {
  double loss = 0, hs_psnr_db = 0, depth_rmse_m = 0, depth_mae_m = 0, peak = 0;
  // Baselines on the same patches and pixels (train/baselines.h): the
  // upsampling cube of the same sensor image, and the constant depth.
  double baseline_hs_psnr_db = 0, baseline_depth_rmse_m = 0, baseline_depth_mae_m = 0;
  // With the pre-inversion on: the Wiener baseline (baselines.h) on the same
  // patches; NaN when the network has no pre-inversion.
  double baseline_wiener_hs_psnr_db = std::nan("");
  // Fraction of pixels whose depth sigmoid is within 0.02 of 0 or 1 (saturated).
  double depth_saturated = 0;
};

}  // namespace hsd::train
