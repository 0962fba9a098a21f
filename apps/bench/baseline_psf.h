// The straightforward PSF computation that Python code usually does, kept as
// the benchmark's baseline (not used by hsd itself): for every (λ, z) the pupil
// field (same phases as hsd) is zero-padded 2× and FFT'd; the FFT's sensor
// pitch λs/(2Nδ) differs per wavelength, so the intensity is resampled to the
// pixel grid by bilinear interpolation and each pixel is point-sampled at its
// centre. Differentiable like the real thing.
#pragma once
#include <torch/types.h>

#include "optics/psf.h"

namespace hsd::bench {

// Returns [L, Z, P, P], each slice normalised to sum 1. `aperture` float64 [N, N].
torch::Tensor baseline_fft_psf(const optics::PsfSpec& spec, const torch::Tensor& aperture, const torch::Tensor& height_m);

}  // namespace hsd::bench
