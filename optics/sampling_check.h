// Checks that the discretisation can represent the physics, with numbers:
//  * pupil sampling: each DOE sample is a cell of constant height, so what the
//    sampling must resolve is the smooth part of the integrand, the source and
//    propagation chirps plus the tilt toward the window's edge pixels. Its
//    largest step between neighbouring samples, k δ (D/2 · |1/z + 1/s| + x_edge/s),
//    must stay below π, or the midpoint rule aliases. (The DOE's own steps,
//    including genuine discontinuities such as the spiral's wing edges, are the
//    element's design, not a sampling error.)
//  * DOE-grid period: the sampled pupil repeats the PSF every λs/δ on the sensor;
//    that period must exceed the window;
//  * the tilt's phase ramp across a cell at the window edge, B = πPpδ/(2λs),
//    must stay small for the cross term of the cell integration (warn > 0.5);
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

// energy_in_window [L, Z] (may be undefined to skip that check).
SamplingReport check_sampling(const PsfSpec& spec, const torch::Tensor& energy_in_window, double energy_warn_threshold);

}  // namespace hsd::optics
