// Fisher information and the Cramér–Rao lower bound of a DOE's PSF for the
// two quantities the camera encodes, inverse depth D = 1/z [1/m] and
// wavelength λ [nm], with the point's lateral position and brightness unknown
// (Shechtman, Sahl, Backer & Moerner, PRL 113, 133902 (2014), "Optimal point
// spread function design for 3D imaging", estimate the position jointly;
// Baek et al. 2021 use the Fisher design to initialise end-to-end training):
//   μ = a · N · PSF(x − x_s, y − y_s; D, λ, h)   expected signal photons per pixel
//       (N photons per point; a = 1 a brightness scale; (x_s, y_s) a shift of
//       the PSF on the sensor in pixels, which is what a lateral move of the
//       source does in this shift-invariant Fresnel model)
//   θ = (D, λ, x_s, y_s, a): the first two of interest, the others nuisance
//       parameters as fisher.nuisance lists them (default all three)
//   I_ij = Σ_pixels (∂μ/∂θ_i)(∂μ/∂θ_j) / (μ + b)   (Poisson noise with b background photons
//                                                  per pixel; μ + b floored at 1e-12)
//   the bound of (D, λ) is the (D, λ) block of I⁻¹, i.e. the inverse of the
//   Schur complement S = I_AA − I_AB I_BB⁻¹ I_BA (A: interest, B: nuisance);
//   CRLB_i = sqrt((S⁻¹)_ii). A PSF that only shifts sideways with λ looks
//   informative with a known position and is not once the position is unknown;
//   a change of in-window energy no longer counts once the brightness is unknown.
// The PSF is the same Fresnel model as psf.h (pupil A·exp(i 2π(η(λ)−1)h/λ),
// defocus chirp, matrix Fourier transform to Gauss–Legendre nodes inside each
// pixel, as the fraction of the aperture's light per pixel, so light that leaves
// the window is lost), written with plain torch ops in float64
// so that autograd gives ∂μ/∂θ (a double backward through a dummy weight) and,
// for the design, the gradient of the CRLB with respect to the height map.
// η(λ) is linearised around each band centre with the material's own slope.
// A singular or ill-conditioned I (a rotationally symmetric PSF is unchanged
// by some parameter changes; at exact focus ∂μ/∂D = 0) is inverted with a
// 1e-12·trace ridge and its condition number reported; nothing becomes NaN,
// and the default aggregate caps each grid point so one such point cannot
// dominate it.
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
// shift_x_px, shift_y_px (0-dim, optional, may require grad): the PSF moved by
// that many pixels along +x (columns) and +y (rows) on the sensor.
torch::Tensor point_psf(const FisherGeometry& g, const torch::Tensor& height_m, const torch::Tensor& inv_depth,
                        const torch::Tensor& wavelength_nm, double eta0, double deta_dnm,
                        const torch::Tensor& shift_x_px = {}, const torch::Tensor& shift_y_px = {});

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
// The bound of the first n_interest parameters when the others are unknown:
// crlb_from_fisher of the Schur complement I_AA − I_AB (I_BB + ridge)⁻¹ I_BA
// (= sqrt of the diagonal of the A block of I⁻¹); `fisher` and `condition`
// are the complement's. n_interest = K: crlb_from_fisher(fisher).
Crlb crlb_with_nuisance(const torch::Tensor& fisher, int64_t n_interest);

struct CrlbReport {
  std::vector<double> wavelengths_nm, inv_depths;  // the grid
  torch::Tensor crlb_inv_depth, crlb_wavelength_nm;  // [Λ, Z] per grid point
  torch::Tensor condition;                           // [Λ, Z] condition number of the (D, λ) information
  double max_condition = 0;
  // Per grid point the bound in units of one layer and one band,
  // t = sqrt(((σ_D/ΔD)² + (σ_λ/Δλ)²)/2), ΔD the inverse-depth spacing of the
  // config's layers, Δλ the band width; aggregated over the grid three ways:
  double aggregate_mean = 0;     // mean of t (the earlier aggregate; one singular point dominates it)
  double aggregate_median = 0;   // median of t (lower median)
  double aggregate_capped = 0;   // mean of min(t, cap)
  torch::Tensor aggregate;  // 0-dim: the one FisherSettings::aggregate names; differentiable in the height map when requested
  std::vector<NuisanceParam> nuisance;
};

struct FisherSettings {
  double photons = 1e4, background = 10.0;   // per point source image; per pixel
  std::vector<double> wavelengths_nm, depths_m;  // the evaluation grid
  double inv_depth_spacing = 1.0, band_width_nm = 10.0;  // aggregation scales
  std::vector<NuisanceParam> nuisance{NuisanceParam::x, NuisanceParam::y, NuisanceParam::N};  // unknown besides (D, λ)
  CrlbAggregate aggregate = CrlbAggregate::capped_mean;
  double aggregate_cap = 10.0;                         // cap of t per grid point (layers/bands)
};

// InputError unless s.aggregate_cap is valid.
void check_aggregate(const FisherSettings& s);
// r.aggregate (the one s.aggregate names, differentiable) and the three
// aggregate_* values from the per-point bounds t (any shape).
void set_aggregates(CrlbReport& r, const torch::Tensor& t, const FisherSettings& s);

// The CRLB over the grid for height_m; differentiable in height_m when it requires grad.
CrlbReport crlb_report(const FisherGeometry& g, const Material& material, const torch::Tensor& height_m,
                       const FisherSettings& s);

}  // namespace hsd::optics
