// Zernike polynomials on the aperture disk (Noll 1976 ordering and
// normalisation: j = 1 piston, 2-3 tilts, 4 defocus, 5-6 astigmatism, ...;
// each has unit RMS over the unit disk). The Fisher design's default basis.
#pragma once
#include <torch/types.h>

namespace hsd::optics {

// Zernike j (Noll, j >= 1) at normalised polar coordinates (rho in [0, 1], theta); 0 outside the disk.
torch::Tensor zernike(int64_t j, const torch::Tensor& rho, const torch::Tensor& theta);

// Modes j = first..first+count-1 on an N×N grid of pitch p over a disk of
// diameter D: float64 [count, N, N] (rows y, columns x, as the DOE grid).
torch::Tensor zernike_basis(int64_t first, int64_t count, int64_t n, double pitch_m, double diameter_m);

}  // namespace hsd::optics
