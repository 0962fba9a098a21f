// Fresnel propagation from the DOE plane to chosen sensor points by a matrix
// Fourier transform (Soummer et al., Opt. Express 15, 15935 (2007), "Fast
// computation of Lyot-style coronagraph propagation").
//
// The paper's PSF (its "Differentiable Point Spread Function" section):
//   P_λ,z(x, y) ∝ | ∬ A e^{i k [(ξ²+η²)/(2z) + (η_λ−1) h(ξ,η) + (ξ²+η²)/(2s)]}
//                    e^{−i 2π (xξ + yη)/(λs)} dξ dη |²
// The quadratic phases and the Fourier kernel are separable in ξ and η, the DOE
// term is not. With the 1-D kernel
//   K_λ,z[m, j] = exp(−i 2π x_m ξ_j/(λs)) · exp(i k ξ_j² (1/z + 1/s)/2)
// and the pupil field M_λ = A ⊙ exp(i k (η_λ−1) h), the field at sensor points
// (y_r, x_c) is F = K M Kᵀ (two matrix products), evaluated exactly at the
// pixel-grid sample positions for every λ: no per-wavelength pitch drift and no
// resampling. The sum over samples is the midpoint rule for the continuous
// integral (each DOE sample is one cell of area δ²).
//
// Functional layer: pure functions of tensors; PsfSimulator (psf.h) is the thin
// stateful layer above.
#pragma once
#include <torch/types.h>

namespace hsd::optics {

// Wraps a float64 phase to [−π, π) (differentiable, gradient 1).
torch::Tensor wrap_phase(const torch::Tensor& phase_rad);

// Unit phasor exp(i·phase): phase float64 (any shape) is wrapped, then cast to
// the real type of `complex_dtype` before cos/sin; returns `complex_dtype`.
torch::Tensor phasor(const torch::Tensor& phase_rad, c10::ScalarType complex_dtype);

// z-independent part of the kernel: exp(−i 2π x_m ξ_j/(λs)), [M, N] complex.
// sensor_x_m float64 [M], pupil_x_m float64 [N].
torch::Tensor compute_tilt_kernel(const torch::Tensor& sensor_x_m, const torch::Tensor& pupil_x_m,
                                  double wavelength_m, double sensor_distance_m, c10::ScalarType complex_dtype);

// Quadratic phase exp(i k ξ² (1/z + 1/s)/2) on the pupil coordinates, [N] complex:
// the source's spherical wave and the Fresnel propagator's chirp together.
torch::Tensor compute_defocus_chirp(const torch::Tensor& pupil_x_m, double wavelength_m, double depth_m,
                                    double sensor_distance_m, c10::ScalarType complex_dtype);

// Cell integration. Each DOE cell (width δ) has constant height, but the smooth
// phases vary across it; the midpoint rule takes their value at the cell centre.
// Integrating a phase of local slope β exactly over the cell gives the factor
// sinc(βδ/2) = sin(βδ/2)/(βδ/2) (real). Applied per axis to the two smooth
// terms separately: the chirp's slope k(1/z + 1/s)ξ (a factor per pupil sample)
// and the tilt's k x/s (a factor per sensor point: the cell-shape envelope of a
// pixelated DOE). The exact factor of the summed slope, sinc(A − B) with
// A = k(1/z + 1/s)ξδ/2 and B = k x δ/(2s), is to first order in the small B
//   sinc(A − B) ≈ sinc(A)·sinc(B) − B·sinc'(A),
// the product plus a cross term that is itself separable: a second kernel
// term diag(B) T diag(chirp ⊙ (−sinc'(A))) ("sinc_cross"; the kernels below
// take G = 2 terms). Without it ("sinc") the error is second order in δ.
// slope_rad_per_m float64 (any shape) -> float64 of the same shape.
torch::Tensor cell_average_factor(const torch::Tensor& slope_rad_per_m, double cell_m);
// −sinc'(u) at u = slope·δ/2 (the cross term's pupil factor), float64.
torch::Tensor cell_cross_factor(const torch::Tensor& slope_rad_per_m, double cell_m);

// Pupil field M = A ⊙ exp(i k (η−1) h): A float64 [N, N] transmission, h [N, N]
// height in metres (any real dtype, may require grad). The phase is formed in
// float64 and wrapped before the cast. Returns complex [N, N].
torch::Tensor compute_pupil_field(const torch::Tensor& aperture, const torch::Tensor& height_m,
                                  double wavelength_m, double refractive_index, c10::ScalarType complex_dtype);

// F_z = K_z M K_zᵀ for a batch of kernels K [Z, M, N] and one field M [N, N]:
// returns complex [Z, M, M] (rows y, columns x). One large GEMM for K·M over
// all z, then a batched product.
torch::Tensor matrix_fourier_transform(const torch::Tensor& kernels, const torch::Tensor& pupil_field);

// |F_z|² with F_z = K_z M K_zᵀ and K_z = tilt ⊙ chirp_z (row-broadcast), as one
// autograd node that stores only the field's output F [Z, M, M] and the small
// factors tilt [M, N] and chirps [Z, N]: the kernels [Z, M, N] are rebuilt in
// the backward pass instead of being kept (they are the largest tensors of the
// PSF). Differentiable in `pupil_field` only. Returns real [Z, M, M].
// With G kernel terms, K_z = Σ_g tilt_g ⊙ chirp_z,g: tilt [G, M, N], chirps [Z, G, N].
torch::Tensor mft_intensity(const torch::Tensor& tilt, const torch::Tensor& chirps, const torch::Tensor& pupil_field);

// Low-rank form of the tilt kernel on the window: T ≈ left · right with
// left [M, r] = U_r Σ_r and right [r, N] = V_rᴴ from the SVD of T (computed in
// complex128), keeping singular values above rel_tol · σ_max. Restricted to a
// window of half-width X, exp(−i2π x ξ/(λs)) has numerical rank close to the
// time-bandwidth product 2X·D/(λs) (prolate spheroidal theory), far below the
// M = P·n rows, so the products below cost r·N² instead of M·N².
struct LowRankKernel {
  torch::Tensor left, right;  // complex [M, r], [r, N] in the requested dtype
};
LowRankKernel factor_tilt_kernel(const torch::Tensor& tilt, double rel_tol, c10::ScalarType complex_dtype);

// |F_z|² as mft_intensity, with K_z ≈ left · (right ⊙ chirp_z):
// F_z = left (W_z M W_zᵀ) leftᵀ, W_z = right ⊙ chirp_z. One autograd node that
// stores F and the small factors; differentiable in `pupil_field` only.
// With G kernel terms sharing `right`: left [M, G·r] (the terms' left factors
// side by side), chirps [Z, G, N]; W_z stacks right ⊙ chirp_z,g over g.
torch::Tensor mft_intensity_low_rank(const LowRankKernel& kernel, const torch::Tensor& chirps,
                                     const torch::Tensor& pupil_field);

// Joint low-rank form of one wavelength's kernels over all depths. The
// stacked kernels [K_1; …; K_Z] ([Z·M, N]) are factored as L·B with B [R, N]
// orthonormal rows (the dominant right singular vectors of the stack, singular
// values above rel_tol · σ_max) and L_z = K_z Bᴴ [M, R]. Then
//   F_z = K_z M K_zᵀ ≈ L_z (B M Bᵀ) L_zᵀ,
// and every depth shares one product with the pupil field, R·N² instead of
// Z·G·r·N². The kernels differ between depths only by the defocus chirp
// exp(i k ξ²/(2z)), so the stack has rank close to one depth's: measured on
// the paper config, R = 39–56 against Z·G·r = 462–672 rows (docs/benchmarks.md).
// kernels: complex [Z, M, N] (complex128 recommended). Computed from the
// stack's Gram matrix [N, N] in complex128 by a randomised range finder.
struct DepthBasis {
  torch::Tensor left;   // complex [Z, M, R] (L_z)
  torch::Tensor basis;  // complex [R, N] (B, orthonormal rows)
};
DepthBasis factor_depth_kernels(const torch::Tensor& kernels, double rel_tol, c10::ScalarType complex_dtype);

// |F_z|² with F_z = L_z (B M Bᵀ) L_zᵀ for left [Z, M, R] and basis [R, N], as one
// autograd node that stores F and the factors; differentiable in `pupil_field`
// only. Returns real [Z, M, M].
torch::Tensor mft_intensity_depth_basis(const DepthBasis& kernel, const torch::Tensor& pupil_field);

// Intensity re² + im² of a complex tensor (never complex abs).
torch::Tensor intensity(const torch::Tensor& field);

}  // namespace hsd::optics
