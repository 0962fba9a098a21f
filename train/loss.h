// The training loss (Baek et al. 2021, "Loss"):
//   L = α·mean|Î − I| + β·mean|D̂ − D| + γ·mean|∇D̂|,   D = 1/Z (inverse depth, 1/m)
// or, with the depth term in metres (train.depth_loss = "metric_l1"),
//   β·mean|1/D̂ − 1/D| = β·mean|Ẑ − Z|
// (the evaluation's unit; both are minimised by the same constant, the median,
// so the constant-depth baseline is the optimum of either), or squared
// (train.depth_loss = "metric_l2"),
//   β·mean (Ẑ − Z)²   [m²],
// the evaluation's RMSE squared. An L1 term is minimised by the median of the
// depths a prediction cannot tell apart, the same in 1/m and in m (the median
// is invariant under 1/x), so where the evidence allows both 1 m and 2 m an L1
// head picks one of them; the squared term is minimised by their mean in
// metres, the estimate of least RMSE.
// The cube term is the paper's L1 or, with train.hs_loss = "l2", the squared
// error α·mean (Î − I)², which PSNR measures: a squared term is minimised by
// the conditional mean of the cubes an image allows (the linear minimum-mean-
// square-error cube the spectral Wiener residual starts from is its Gaussian
// form), an L1 term by their median. LossTerms::hs is mean |Î − I| either way
// (the logged train_hs_l1); the total carries the chosen term.
// The total-variation term acts on the prediction (the paper writes ∇D; the
// gradient of the ground truth is a constant). Means run over valid pixels
// (mask) when a mask is given.
#pragma once
#include <torch/types.h>

#include "common/choices.h"

namespace hsd::train {

struct LossWeights {
  double alpha = 1.0, beta = 1e-2, gamma = 1e-2;
  DepthLoss depth_loss = DepthLoss::inverse_l1;  // the depth term (see above)
  HsLoss hs_loss = HsLoss::l1;                    // the cube term (see above)
  // The bins head (model.depth_bins): + ce · mean_pixels(−Σ_k q_k log p_k),
  // q the two-hot target of the true normalised inverse depth
  // u = (1/Z − inv_far)/(inv_near − inv_far), clamped to [0, 1], split
  // linearly between the bins t_k = k/(N−1) around it.
  double ce = 0.0;
  double inv_far = 0.5, inv_near = 2.5;  // 1/m, the head's range (the network's)
};

struct LossTerms {
  torch::Tensor total, hs, depth, tv, ce;  // scalars; total carries the gradient (ce: zero without bins)
};

// The two-hot targets [B, N, H, W] of inv_true [B, 1, H, W] over N bins (see LossWeights::ce).
torch::Tensor two_hot_depth_targets(const torch::Tensor& inv_true, int64_t bins, double inv_far, double inv_near);

// The cube term alone, unweighted: mean (Î − I)² for HsLoss::l2, mean |Î − I|
// for l1, over the valid pixels of mask [B, 1, H, W] (or all). hs_pred, hs_true [B, L, H, W].
torch::Tensor cube_term(const torch::Tensor& hs_pred, const torch::Tensor& hs_true, HsLoss kind,
                        const torch::Tensor& mask = {});

// hs_pred, hs_true [B, L, H, W]; inv_pred, inv_true [B, 1, H, W] (1/m); mask [B, 1, H, W] or undefined.
LossTerms reconstruction_loss(const torch::Tensor& hs_pred, const torch::Tensor& hs_true, const torch::Tensor& inv_pred,
                              const torch::Tensor& inv_true, const LossWeights& w, const torch::Tensor& mask = {},
                              const torch::Tensor& depth_logits = {});
// depth_logits [B, N, H, W] (the bins head's, NetOutput::depth_logits) or undefined (no cross-entropy term).

}  // namespace hsd::train
