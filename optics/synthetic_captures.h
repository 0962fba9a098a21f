// A synthetic lab bench: the frames a camera records of a point source through
// a DOE, for hsd_calibrate's example folder and the simulated-prototype round
// trip (docs/camera.md). Per (band, depth), in
// 16-bit sensor counts:
//   frame = clip(round(Poisson(k·P + background) + Poisson(hot) + dark_level + N(0, σ_r²)), 0, 65535)
// with P the PSF on the frame (the optical axis at the frame centre plus
// axis_offset_px, placed by a sub-pixel Fourier shift), k the exposure that
// puts the brightest pixel at peak_counts, "hot" the dark current of a fixed
// set of hot pixels (2,000-20,000 counts, Poisson in every frame), and the
// dark frame the same with the source off (stray light and dark current only). Every slice (and the dark frame) is
// recorded `exposures` times with independent noise.
#pragma once
#include <cstdint>
#include <utility>

#include <torch/types.h>

#include "common/config.h"

namespace hsd::optics {

struct SyntheticCaptures {
  torch::Tensor frames;                // float64 [L, Z, E, F, F], whole counts in [0, 65535]
  torch::Tensor dark;                  // float64 [E, F, F]
  torch::Tensor hot;                   // bool [F, F], the hot pixels
  std::pair<double, double> axis_px;   // the optical axis in the frame (row, col)
};

// psf_frames [L, Z, F, F]: each slice the PSF on the whole frame with the axis
// at the centre pixel (F odd), any normalisation.
SyntheticCaptures synthesize_captures(const torch::Tensor& psf_frames, const SyntheticCaptureConfig& cfg, uint64_t seed);

}  // namespace hsd::optics
