// Measured PSFs from point-source captures (the paper's prototype, "HS-D
// Imaging Prototype": the fabricated DOE's PSFs are captured and the network is
// fine-tuned on them). One frame [H, W] per (band, depth), linear sensor counts:
//   1. the dark frame is subtracted (when given);
//   2. hot pixels are replaced by the median of their 8 neighbours: a pixel
//      more than hot_pixel_sigma noise σ above that median and more than
//      hot_pixel_ratio times its brightest neighbour (a pixel-integrated PSF
//      core is never that isolated: its neighbours hold at least ~1/3 of it);
//   3. noise σ (and, with estimate_background, the background b; else b = 0:
//      the dark frame, taken with the source off, held it): 1.4826 × MAD and
//      median of the frame's outer
//      ring (1/16 of its size, at least 4 px wide) outside the (P + 16)² box
//      around the PSF (its outermost pixels when the frame is too small for
//      that). The frame must be large enough for the blur's light to fade
//      before the ring: a band blurred beyond its window spreads light far
//      outside it, which would be taken for background;
//   4. centroid c of (frame − b) inside the P × P box, iterated to convergence;
//   5. registration: the frame is shifted (Fourier shift theorem, sub-pixel)
//      so that the registration point (c, or the optical axis when given)
//      lands on the window's centre pixel (the background-subtracted frame
//      zero-padded to a smooth FFT size), and the P × P window is cut out;
//   6. the window is normalised to sum 1 (zero-mean noise is kept, not
//      clipped: clipping would bias every slice by the noise's positive part).
// Pixel coordinates: (row, column) with pixel centres at integers, row index
// growing with +y (optics/conventions.h).
#pragma once
#include <optional>
#include <string>
#include <utility>

#include <torch/types.h>

#include "common/config.h"

namespace hsd::optics {

struct CapturedPsf {
  torch::Tensor psf;                        // float64 [P, P], sums to 1
  std::pair<double, double> centroid_px;    // in the frame, (row, col)
  double background = 0.0;                  // counts per pixel (after the dark frame)
  double noise_sigma = 0.0;                 // counts
  double snr = 0.0;                         // peak of (frame − background) over σ
  double energy_in_window = 0.0;            // light in the P × P window over the frame's
  int64_t hot_pixels = 0;                   // replaced
};

// frame, dark: [H, W] counts (dark undefined = none); P the odd window;
// axis_px: register to this point instead of the centroid. `saturation`:
// counts at which the sensor clips (0 = unknown). InputError naming `file`
// (exit 2) for a frame smaller than P, a saturated pixel (not a hot pixel), a
// peak below opt.min_snr noise σ, or a window that would leave the frame.
CapturedPsf calibrate_capture(const torch::Tensor& frame, const torch::Tensor& dark, int64_t P,
                              const CalibrationConfig& opt, double saturation,
                              const std::optional<std::pair<double, double>>& axis_px, const std::string& file,
                              bool estimate_background = true);

// Hot pixels of a frame [H, W] (rule 2 above with noise σ): a bool mask.
torch::Tensor find_hot_pixels(const torch::Tensor& frame, double sigma, double n_sigma, double ratio);

// The frame [H, W] shifted by (dy, dx) pixels (content moves towards +row,
// +col), by the Fourier shift theorem on the frame zero-padded by at least
// 8 px to a smooth FFT size (subtract any background first); float64.
torch::Tensor fourier_shift(const torch::Tensor& frame, double dy, double dx);

// Centroid (row, col) of img [H, W] in its own pixel coordinates.
std::pair<double, double> image_centroid(const torch::Tensor& img);

}  // namespace hsd::optics
