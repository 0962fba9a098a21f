// The guided filter (He, Sun and Tang, "Guided Image Filtering", ECCV 2010 /
// TPAMI 2013, their Eqs. 1, 5, 6 and 8): an edge-preserving local mean of an
// input p steered by a guide image I. In every (2r+1)² window ω_k the output
// is a linear function of the guide, q = a_k I + b_k, fitted to p by least
// squares with a ridge ε on a_k:
//   a_k = (mean_ω(I p) − mean_ω(I) mean_ω(p)) / (var_ω(I) + ε),
//   b_k = mean_ω(p) − a_k mean_ω(I),
// and each pixel averages the coefficients of the windows that hold it:
//   q_i = mean_ω(a)_i I_i + mean_ω(b)_i.
// Where the guide is flat (var ≪ ε) q is the box mean of the box mean of p;
// across an edge of the guide (var ≫ ε) q follows the guide's step instead of
// blurring it. Linear in p; a constant p is returned unchanged. Windows are
// cut at the image border (the mean over their part inside the image), so
// the result is the same whatever lies outside and a tile of a larger image
// gets the same pixels wherever its context reaches r + r px.
#pragma once
#include <torch/types.h>

namespace hsd::model {

// x [B, C, H, W] -> the mean over the (2r+1)² box around each pixel, counting
// only pixels inside the image (r >= 0; r = 0 returns x).
torch::Tensor box_mean(const torch::Tensor& x, int64_t radius_px);

// guide [B, 1, H, W], input [B, K, H, W] (the same dtype, float32 or float64),
// radius r >= 0 px, eps > 0 (in the guide's units squared) -> [B, K, H, W],
// each of the K channels filtered with the same guide. Differentiable in both.
torch::Tensor guided_filter(const torch::Tensor& guide, const torch::Tensor& input, int64_t radius_px, double eps);

}  // namespace hsd::model
