// Resampling a spectral scene's bands to the config's band centres by band
// integration: the scene's channels are samples of a piecewise-linear spectrum
// (held constant for half a channel spacing beyond the first and last channel),
// and a target band's value is that spectrum's exact mean over
// [λ_b − Δ/2, λ_b + Δ/2], the same convention as the camera response
// (optics/spectrum.h).
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

#include "data/scene_exr.h"

namespace hsd::data {

// R [L_out, L_in] float64 with out = R · in (per pixel). InputError naming
// `what` when a target band reaches beyond the channels (by more than half a
// channel spacing).
torch::Tensor band_resampling_matrix(const std::vector<double>& in_m, const std::vector<double>& centres_m,
                                     double band_width_m, const std::string& what);

// True when both lists hold the same wavelengths (to 1e-3 nm).
bool same_bands(const std::vector<double>& a_m, const std::vector<double>& b_m);

// The scene on the given bands: unchanged when the bands already match,
// otherwise resampled with a warning naming `path` and both band sets.
SpectralScene resample_scene_bands(SpectralScene scene, const std::vector<double>& centres_m, double band_width_m,
                                   const std::string& path);

}  // namespace hsd::data
