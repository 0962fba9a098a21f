// K-level lithography of a DOE height map (hsd_fabricate): the standard binary
// multi-level process (Swanson, "Binary optics technology", MIT Lincoln Lab.
// TR 854, 1989). Heights in [0, H) are rounded to the levels q·Δ, Δ = H/K,
// q ∈ {0 .. K−1}; a height that rounds to K is a full period (2π at the design
// wavelength) and wraps to q = 0. m = log2 K binary masks make the levels:
// mask k covers the cells whose q has bit k set and adds 2^k Δ of height
// there, so the quantised map is exactly
//   h_q = Δ Σ_k 2^k mask_k.
// The scalar first-order efficiency of K levels is sinc²(1/K) = [sin(π/K)/(π/K)]²
// (Swanson's Eq. 4): 0.405 for 2 levels, 0.95 for 8, 0.987 for 16.
// Grids follow optics/conventions.h: sample [i, j] at x = (j − (N−1)/2)·δ,
// y = (i − (N−1)/2)·δ, each sample a square cell of side δ.
#pragma once
#include <cstdint>
#include <vector>

#include <torch/types.h>

namespace hsd::optics {

struct LevelMap {
  torch::Tensor level;  // int64 [N, N], q in [0, K)
  double step_m = 0;    // Δ = H / K [m]
  int64_t levels = 0;   // K
};

// height_m [N, N] (any float dtype; heights outside [0, H) are wrapped into it
// first, as the DOE's phase is), max_height_m H > 0, levels K >= 2 (a power of
// two). InputError-free: the caller validates K.
LevelMap quantize_to_levels(const torch::Tensor& height_m, double max_height_m, int64_t levels);

// The quantised heights q·Δ, float64 [N, N].
torch::Tensor level_heights(const LevelMap& q);

// m = log2 K, the number of binary masks of K levels.
int64_t level_mask_count(int64_t levels);

// The m = log2 K binary masks, bool [m, N, N]: masks[k] = bit k of q.
torch::Tensor level_masks(const LevelMap& q);

// Δ Σ_k 2^k masks[k], float64 [N, N] (masks bool or integer [m, N, N]; the
// sum is formed in integers, so it equals level_heights bit for bit).
torch::Tensor height_from_masks(const torch::Tensor& masks, double step_m);

// RMS of the phase-equivalent height error of the quantisation: (h_q − h)
// wrapped into [−H/2, H/2) (a height off by a full period is no error), over
// every cell [m].
double quantisation_rms_m(const torch::Tensor& height_m, const LevelMap& q, double max_height_m);

// Cells per level q (K counts): the fabricated height histogram.
std::vector<int64_t> level_histogram(const LevelMap& q);

// Lines (runs of covered cells) and spaces (runs of uncovered cells) of one
// mask along its rows and columns; runs that touch the grid's border are not
// features (their true extent is unknown) and are skipped.
struct MaskFeatures {
  int64_t min_line_cells = 0;   // 0: no interior line
  int64_t min_space_cells = 0;  // 0: no interior space
  int64_t lines_below = 0;      // runs narrower than the minimum feature
  int64_t spaces_below = 0;
  double covered_fraction = 0;  // of the grid
};
// mask bool [N, N]; min_feature_cells: the process's minimum in cells (runs of
// fewer cells are counted as below it).
MaskFeatures mask_features(const torch::Tensor& mask, double min_feature_cells);

// Rectangles of cells that cover a mask exactly, without overlap: each row's
// runs, merged with the identical run of the rows above. Cells [row0, row0 +
// rows) × [col0, col0 + cols).
struct CellRect {
  int64_t row0 = 0, col0 = 0, rows = 0, cols = 0;
};
std::vector<CellRect> mask_rectangles(const torch::Tensor& mask);

}  // namespace hsd::optics
