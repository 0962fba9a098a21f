// Evaluation metrics (Baek et al. 2021, Tables 1-2 and the ColorChecker study):
//   PSNR = 10 log10(R² / MSE), R the data range (hsd uses the ground truth's
//     maximum over the scene, stated in every report); identical images give
//     +inf, reported as 100 dB.
//   SSIM per Wang, Bovik, Sheikh & Simoncelli 2004: 11×11 Gaussian window
//     (σ = 1.5), K1 = 0.01, K2 = 0.03, over the window positions fully inside
//     the image, per channel, averaged over channels.
//   Luminance Y = Σ_λ ȳ(λ) E(λ) · R(λ) / Σ_λ ȳ(λ) E(λ) of a reflectance cube (or
//     Σ_λ ȳ(λ) S(λ) / Σ_λ ȳ(λ) of radiance).
//   Every metric is over the valid pixels (the scene's mask), as training sees
//   only valid pixels.
//   Depth RMSE and MAE in metres.
//   ColorChecker: recovered reflectance = radiance / illuminant, averaged in
//     each patch's box; RMSE over bands per patch, mean over the 24 patches.
#pragma once
#include <array>
#include <vector>

#include <torch/types.h>

namespace hsd::train {

constexpr double kPsnrCapDb = 100.0;

// a, b [C, H, W] (any float); data_range > 0; mask [1, H, W] (1 = valid) or
// undefined (every pixel). PSNR: the MSE over the valid pixels. SSIM: the mean
// of the SSIM map over the window positions whose whole window is valid (NaN
// when there is none).
// NaN or Inf in either image is a NumericalError naming the first bad pixel
// (never a number, never the 100-dB cap); so is one in depth_errors' prediction.
double psnr_db(const torch::Tensor& a, const torch::Tensor& b, double data_range, const torch::Tensor& mask = {});
double ssim(const torch::Tensor& a, const torch::Tensor& b, double data_range, const torch::Tensor& mask = {});

// The interior of a valid mask: mask [1, H, W] (1 = valid) with every pixel
// closer than margin_px to the image's border set to 0 (margin_px >= 0; a
// pixel is interior when margin_px <= y < H - margin_px, likewise x). The
// evaluator scores it beside whole scenes: a training patch's pixels lie at
// least the rendering margin (the PSF's reach) inside their scene, where the
// image does not depend on how the renderer continues the scene past it.
torch::Tensor interior_mask(const torch::Tensor& mask, int64_t margin_px);

// Weighted band sum: cube [L, H, W], weights [L] (normalised here to sum 1) -> [1, H, W].
torch::Tensor luminance(const torch::Tensor& cube, const torch::Tensor& weights);

struct DepthErrors {
  double rmse_m = 0, mae_m = 0;
};
// pred, truth [1, H, W] metres; mask [1, H, W] (1 = valid) or undefined.
DepthErrors depth_errors(const torch::Tensor& pred, const torch::Tensor& truth, const torch::Tensor& mask = {});

// radiance [L, H, W] -> mean recovered reflectance per box (radiance / illuminant), [K, L];
// boxes [x0, y0, x1, y1).
torch::Tensor patch_reflectances(const torch::Tensor& radiance, const torch::Tensor& illuminant,
                                 const std::vector<std::array<int64_t, 4>>& boxes);
// Mean over patches of the RMSE over bands: recovered, truth [K, L].
double mean_patch_rmse(const torch::Tensor& recovered, const torch::Tensor& truth);

}  // namespace hsd::train
