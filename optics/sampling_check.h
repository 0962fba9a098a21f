// Checks that the discretisation can represent the physics, with numbers:
//  * pupil sampling: the largest phase step between neighbouring DOE samples of
//    the integrand (source and propagation chirps, the DOE phase modulo 2π, and
//    the tilt toward the window's edge pixels) must stay below π, or the
//    midpoint rule aliases;
//  * DOE-grid period: the sampled pupil repeats the PSF every λs/δ on the sensor;
//    that period must exceed the window;
//  * energy_in_window below a threshold: the window misses light.
// Each problem becomes one warning naming (λ, z) and the numbers.
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

#include "optics/psf.h"

namespace hsd::optics {

struct SamplingReport {
  torch::Tensor max_phase_step_rad;  // float64 [L, Z]
  std::vector<double> period_pixels; // [L] λs/(δ p)
  std::vector<std::string> warnings;
};

// height_m [N, N]; energy_in_window [L, Z] (may be undefined to skip that check).
SamplingReport check_sampling(const PsfSpec& spec, const torch::Tensor& aperture, const torch::Tensor& height_m,
                              const torch::Tensor& energy_in_window, double energy_warn_threshold);

}  // namespace hsd::optics
