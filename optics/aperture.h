// Aperture transmission A(x, y) on the DOE grid. Edge samples get the fraction
// of their δ×δ cell that lies inside the aperture (8×8 supersampling), so the
// sampled aperture has the right area and centroid instead of a staircase edge.
#pragma once
#include <string>

#include <torch/types.h>

#include "common/choices.h"

namespace hsd::optics {

// float64 [N, N] in [0, 1]. shape: "circle" (diameter D) or "square" (side D),
// centred on the grid centre (between samples for even N).
torch::Tensor aperture_transmission(int64_t n, double pitch_m, double diameter_m, ApertureShape shape);

// Sample coordinates of an N-point grid of pitch δ centred on 0: (j − (N−1)/2)·δ, float64 [N].
torch::Tensor centred_coordinates(int64_t n, double pitch_m);

}  // namespace hsd::optics
