// Fisher information and the Cramér–Rao lower bound of a DOE's PSF for the
// two quantities the camera encodes, inverse depth D = 1/z [1/m] and
// wavelength λ [nm] (Shechtman, Sahl, Backer & Moerner, PRL 113, 133902 (2014),
// "Optimal point spread function design for 3D imaging"; Baek et al. 2021 use
// the Fisher design to initialise end-to-end training):
//   μ = N · PSF(D, λ; h)               expected signal photons per pixel (N photons per point)
//   I_ij = Σ_pixels (∂μ/∂θ_i)(∂μ/∂θ_j) / (μ + b)   (Poisson noise with b background photons
//                                                  per pixel; μ + b floored at 1e-12)
//   CRLB_i = sqrt((I⁻¹)_ii)
// The PSF is the same Fresnel model as psf.h (pupil A·exp(i 2π(η(λ)−1)h/λ),
// defocus chirp, matrix Fourier transform to Gauss–Legendre nodes inside each
// pixel, as the fraction of the aperture's light per pixel, so light that leaves
// the window is lost), written with plain torch ops in float64
// so that autograd gives ∂μ/∂θ (a double backward through a dummy weight) and,
// for the design, the gradient of the CRLB with respect to the height map.
// η(λ) is linearised around each band centre with the material's own slope.
// A singular or ill-conditioned I (a rotationally symmetric PSF is unchanged
// by some parameter changes) is inverted with a 1e-12·trace ridge and its
// condition number reported; nothing becomes NaN.
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

#include "optics/material.h"
#include "optics/psf.h"

namespace hsd::optics {

struct FisherGeometry {
  double sensor_distance_m = 0, pixel_pitch_m = 0, doe_pitch_m = 0, aperture_diameter_m = 0;
  int64_t doe_samples = 0, window_px = 0, nodes = 2;
  torch::Tensor aperture;  // [N, N] float64
  double aperture_energy = 0;  // Σ A² (Parseval normalisation of the PSF)
  torch::Tensor pupil_x;   // [N] float64 (metres)
  torch::Tensor sensor_x;  // [P·n] float64: node positions, pixel-major
  torch::Tensor weights;   // [n] float64 Gauss–Legendre weights (sum 1)
};
// From a PSF spec (its sensor geometry and DOE grid), with `nodes` per pixel axis.
FisherGeometry make_fisher_geometry(const PsfSpec& spec, int64_t window_px, int64_t nodes);

// PSF [P, P] of a point at inverse depth `inv_depth` [1/m] and
// wavelength `wavelength_nm` (0-dim float64 tensors, may require grad) through
// height_m [N, N] (float64, may require grad), as the fraction of the light
// through the aperture landing in each pixel (sums to the energy in the
// window, <= 1). eta0, deta_dnm: η and dη/dλ [1/nm] at the band centre.
torch::Tensor point_psf(const FisherGeometry& g, const torch::Tensor& height_m, const torch::Tensor& inv_depth,
                        const torch::Tensor& wavelength_nm, double eta0, double deta_dnm);

// Fisher matrix [K, K] from the expected counts mu [P, P] and its derivatives
// dmu[k] [P, P] (any parameters), with background b >= 0.
torch::Tensor fisher_from_jacobian(const torch::Tensor& mu, const std::vector<torch::Tensor>& dmu, double background);

// ∂μ/∂θ_k for scalar parameters θ_k that mu depends on, by autograd (double
// backward); create_graph keeps them differentiable (for the design).
std::vector<torch::Tensor> jacobian_by_autograd(const torch::Tensor& mu, const std::vector<torch::Tensor>& params,
                                                bool create_graph);

struct Crlb {
  torch::Tensor fisher;  // [K, K]
  torch::Tensor crlb;    // [K] (units of the parameters)
  double condition = 0;  // largest / smallest eigenvalue of I (inf if singular)
};
Crlb crlb_from_fisher(const torch::Tensor& fisher);

struct CrlbReport {
  std::vector<double> wavelengths_nm, inv_depths;  // the grid
  torch::Tensor crlb_inv_depth, crlb_wavelength_nm;  // [Λ, Z] per grid point
  double max_condition = 0;
  // Aggregate (dimensionless): mean over the grid of sqrt(((σ_D/ΔD)² + (σ_λ/Δλ)²)/2),
  // ΔD the inverse-depth spacing of the config's layers, Δλ the band width.
  torch::Tensor aggregate;  // 0-dim, differentiable in the height map when requested
};

struct FisherSettings {
  double photons = 1e4, background = 10.0;   // per point source image; per pixel
  std::vector<double> wavelengths_nm, depths_m;  // the evaluation grid
  double inv_depth_spacing = 1.0, band_width_nm = 10.0;  // aggregation scales
};

// The CRLB over the grid for height_m; differentiable in height_m when it requires grad.
CrlbReport crlb_report(const FisherGeometry& g, const Material& material, const torch::Tensor& height_m,
                       const FisherSettings& s);

}  // namespace hsd::optics
