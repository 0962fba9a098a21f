// The errors a fab makes, applied to a DOE height map h [N, N] (metres; the
// paper names fabrication inaccuracy as the cause of its prototype's long-tail,
// low-contrast PSFs). The surface is rendered on a grid refined s times (each
// DOE cell of side δ becomes s × s sub-cells of the same height), so lateral
// errors can move edges by less than a cell. In the order a process makes them:
//   mask misalignment  the map quantised to K levels (optics/lithography.h),
//                      mask k >= 1 moved by d_k = misalignment_m · (cos θ_k,
//                      sin θ_k), θ_k = π/4 + (k − 1)·π/2, against mask 0:
//                      h = Δ Σ_k 2^k mask_k(x − d_k)
//   decentre           the whole map moved by decentre_m against the aperture
//                      (direction decentre_angle_rad from +x; flat substrate,
//                      height 0, moves in at the edge)
//   edge rounding      h <- G_b * h            (Gaussian blur, σ_b = edge_blur_m)
//   etch depth         h <- (1 + e) h          (e = height_scale_error)
//   roughness          h <- h + r,  r ~ N(0, ρ²) white per DOE cell, or that
//                      noise blurred by a Gaussian of σ = roughness_correlation_m
//                      and rescaled to RMS ρ = roughness_rms_m
// Heights are clamped at 0 (no material is removed below the substrate).
// Shifts are exact for whole sub-cells and interpolate linearly between (a
// sub-cell an edge crosses gets the area-weighted mean height); blurs are
// separable with the edge samples replicated.
#pragma once
#include <cstdint>
#include <random>

#include <torch/types.h>

#include "common/config.h"

namespace hsd::optics {

struct FabricationProcess {
  double pitch_m = 0;             // δ, the DOE cell pitch [m]
  int64_t subsamples = 1;         // s: the surface on s × s sub-cells per cell ([N·s, N·s], pitch δ/s)
  double max_height_m = 0;        // H of the levels (for a misalignment)
  int64_t levels = 0;             // K of the levels (for a misalignment; 0 = none: misalignment_m must be 0)
  double decentre_angle_rad = 0;  // direction of decentre_m, from +x towards +y
};

// height_m [N, N] (any float dtype); seed draws the roughness. Returns the
// fabricated surface [N·s, N·s] in the input's dtype and device.
// std::invalid_argument for a misalignment without levels.
torch::Tensor fabricated_surface(const torch::Tensor& height_m, const FabricationErrorConfig& err,
                                 const FabricationProcess& process, uint64_t seed);

// The same on the DOE's own grid (s = 1): hsd_calibrate --make-captures.
torch::Tensor apply_fabrication_error(const torch::Tensor& height_m, const FabricationErrorConfig& err,
                                      const FabricationProcess& process, uint64_t seed);

// Each cell of map [N, N] repeated as s × s sub-cells: [N·s, N·s].
torch::Tensor refine_cells(const torch::Tensor& map, int64_t s);

// map [N, M] moved by (dy, dx) samples (+y = +rows, +x = +columns): linear
// interpolation between whole-sample shifts, zeros move in.
torch::Tensor shift_map(const torch::Tensor& map, double dy_samples, double dx_samples);

// Separable Gaussian blur of a 2-D map with σ in samples (edges replicated);
// σ <= 0 returns the map. Sums of constant maps are kept exactly.
torch::Tensor gaussian_blur_2d(const torch::Tensor& map, double sigma_samples);

// One random draw of the errors whose scales `scales` gives (train.fabrication_noise):
// e ~ N(0, height_scale_error²), roughness of RMS roughness_rms_m (its pattern
// from the seed), edge blur σ ~ U(0, edge_blur_m), decentre ~ U(0, decentre_m)
// in a direction ~ U(0, 2π) (written to *angle_rad). misalignment stays 0.
FabricationErrorConfig draw_fabrication_error(const FabricationErrorConfig& scales, std::mt19937_64& rng, double* angle_rad);

// The error sizes of `e` times f >= 0 (the correlation length kept).
FabricationErrorConfig scaled_fabrication_error(FabricationErrorConfig e, double f);

// True when every error of `e` is zero.
bool no_fabrication_error(const FabricationErrorConfig& e);

}  // namespace hsd::optics
