// The errors a fab makes, applied to a DOE height map h [N, N] (metres; the
// paper names fabrication inaccuracy as the cause of its prototype's long-tail,
// low-contrast PSFs). In the order a process makes them:
//   edge rounding   h <- G_b * h            (Gaussian blur, σ_b = edge_blur_m)
//   etch depth      h <- (1 + e) h          (e = height_scale_error)
//   roughness       h <- h + r,  r ~ N(0, ρ²) white per DOE sample, or white
//                   noise blurred by a Gaussian of σ = roughness_correlation_m
//                   and rescaled to RMS ρ = roughness_rms_m
// Heights are clamped at 0 (no material is removed below the substrate).
// Blurs are separable, with the edge samples replicated.
#pragma once
#include <cstdint>

#include <torch/types.h>

#include "common/config.h"

namespace hsd::optics {

// height_m [N, N] (any float dtype), doe_pitch_m the sample pitch; seed draws
// the roughness. Returns the perturbed map in the input's dtype and device.
torch::Tensor apply_fabrication_error(const torch::Tensor& height_m, const FabricationErrorConfig& err, double doe_pitch_m,
                                      uint64_t seed);

// Separable Gaussian blur of a 2-D map with σ in samples (edges replicated);
// σ <= 0 returns the map. Sums of constant maps are kept exactly.
torch::Tensor gaussian_blur_2d(const torch::Tensor& map, double sigma_samples);

}  // namespace hsd::optics
