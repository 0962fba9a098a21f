// Fisher information of a DOE about inverse depth D = 1/z *through a scene*,
// not a point source. The Fisher design of fisher.h scores a point of known
// spectrum, where every change of the PSF's shape is information; a camera
// looking at textured surfaces sees something else (docs/experiments.md, the DOE ablation:
// designs whose point-source bound is best learned depth worst).
//
// Model (a Whittle likelihood; the scene cue of depth_distinctness.h made a
// bound). The surface at depth z is a stationary Gaussian texture of variance
// a (unknown contrast) and power spectrum S(f) ∝ 1/(|f|² + f₀²), normalised to
// mean 1 over the frequencies; the camera's channel c sees it through the
// channel's PSF h_c = Σ_l Ω_cl PSF_l(D) / Σ_l Ω_cl (fisher.h's point_psf at
// each band centre, the light leaving the window lost) with white noise of
// variance σ² (relative to the texture's). On an N×N grid of frequencies f
// (cycles per pixel) the image's periodogram has mean
//   P_c(f; D, a) = a S(f) |H_c(f; D)|² + σ²,
// the DFT coefficients are independent, and the information of an N²-pixel
// image is
//   I_ij = ½ Σ_c Σ_f (∂_i P_c)(∂_j P_c) / P_c²,   θ = (D, a)
// (½: f and −f are one complex coefficient of a real image); a patch of n
// pixels has n/N² of it. Only the MTF |H| enters: a shift, or a change of the
// PSF that is mostly phase, carries nothing. With the contrast unknown
// ("N" in fisher.nuisance) the bound of D is the Schur complement's, so a
// depth change that only dims the whole image does not count. The bound is
// σ_D = sqrt((I⁻¹)_DD), in 1/m; per depth t = σ_D / ΔD (ΔD the layers'
// inverse-depth spacing), aggregated as fisher.aggregate says.
#pragma once
#include <torch/types.h>

#include "optics/fisher.h"

namespace hsd::optics {

struct SceneFisherSettings {
  torch::Tensor camera_response;  // Ω [C, Λ] float64 over FisherSettings::wavelengths_nm (C >= 1)
  double noise_variance = 1e-3;   // σ² relative to the texture's variance (> 0)
  double corner_cycles_per_px = 1.0 / 64;  // f₀ of S(f)
  int64_t patch_px = 64;          // the bound is for a patch_px² image
};

// Fisher matrix [K, K] of an N×N image from the periodogram means P [C, N, N]
// (> 0) and their derivatives dP[k] [C, N, N]: ½ Σ ∂_iP ∂_jP / P².
torch::Tensor scene_fisher_from_power(const torch::Tensor& power, const std::vector<torch::Tensor>& dpower);

// The camera's channel PSFs [C, P, P] at inverse depth D (0-dim float64, may
// require grad) through height_m [N, N] (float64, may require grad).
torch::Tensor camera_channel_psfs(const FisherGeometry& g, const Material& material, const torch::Tensor& height_m,
                                  const torch::Tensor& inv_depth, const std::vector<double>& wavelengths_nm,
                                  const torch::Tensor& camera_response);

// The scene bound over s.depths_m in CrlbReport form: crlb_inv_depth and
// condition [1, Z]; crlb_wavelength_nm zeros (the scene bound is of depth
// alone); t = σ_D/ΔD. s.nuisance: "N" makes the texture's contrast unknown
// (x and y change nothing in a shift-invariant model). Differentiable in
// height_m when it requires grad.
CrlbReport scene_crlb_report(const FisherGeometry& g, const Material& material, const torch::Tensor& height_m,
                             const FisherSettings& s, const SceneFisherSettings& scene);

}  // namespace hsd::optics
