#include "train/loss.h"

#include <torch/torch.h>

namespace hsd::train {

namespace {
// Mean of x [B, C, H, W] over the pixels where m [B, 1, H, W] is 1 (guarded).
torch::Tensor masked_mean(const torch::Tensor& x, const torch::Tensor& m) {
  if (!m.defined()) return x.mean();
  const torch::Tensor mm = m.expand_as(x);
  return (x * mm).sum() / mm.sum().clamp_min(1.0);
}
}  // namespace

torch::Tensor two_hot_depth_targets(const torch::Tensor& inv_true, int64_t bins, double inv_far, double inv_near) {
  TORCH_CHECK(bins >= 2 && inv_near > inv_far, "two_hot_depth_targets: needs >= 2 bins and inv_near > inv_far");
  const torch::Tensor s = ((inv_true - inv_far) / (inv_near - inv_far)).clamp(0.0, 1.0) * double(bins - 1);
  const torch::Tensor a = s.floor().clamp_max(double(bins - 2));  // the lower bin, [B, 1, H, W]
  const torch::Tensor w = s - a;                                   // the upper bin's share
  const torch::Tensor k = torch::arange(bins, inv_true.options()).view({1, -1, 1, 1});
  return (k == a).to(inv_true.scalar_type()) * (1.0 - w) + (k == a + 1).to(inv_true.scalar_type()) * w;
}

torch::Tensor cube_term(const torch::Tensor& hs_pred, const torch::Tensor& hs_true, HsLoss kind,
                        const torch::Tensor& mask) {
  const torch::Tensor e = hs_pred - hs_true;
  return masked_mean(kind == HsLoss::l2 ? e.square() : e.abs(), mask);
}

LossTerms reconstruction_loss(const torch::Tensor& hs_pred, const torch::Tensor& hs_true, const torch::Tensor& inv_pred,
                              const torch::Tensor& inv_true, const LossWeights& w, const torch::Tensor& mask,
                              const torch::Tensor& depth_logits) {
  LossTerms t;
  const torch::Tensor hs_term = cube_term(hs_pred, hs_true, w.hs_loss, mask);
  t.hs = w.hs_loss == HsLoss::l1 ? hs_term : masked_mean((hs_pred - hs_true).detach().abs(), mask);
  if (w.depth_loss == DepthLoss::inverse_l1) {
    t.depth = masked_mean((inv_pred - inv_true).abs(), mask);
  } else {
    const torch::Tensor dz = 1.0 / inv_pred.clamp_min(1e-6) - 1.0 / inv_true.clamp_min(1e-6);  // Ẑ − Z [m]
    t.depth = masked_mean(w.depth_loss == DepthLoss::metric_l2 ? dz.square() : dz.abs(), mask);
  }
  // Forward differences along x and y (anisotropic TV), over pairs of valid pixels.
  const int64_t H = inv_pred.size(2), W = inv_pred.size(3);
  torch::Tensor tv = torch::zeros({}, inv_pred.options());
  if (W > 1) {
    const torch::Tensor dx = (inv_pred.narrow(3, 1, W - 1) - inv_pred.narrow(3, 0, W - 1)).abs();
    tv = tv + masked_mean(dx, mask.defined() ? mask.narrow(3, 1, W - 1) * mask.narrow(3, 0, W - 1) : mask);
  }
  if (H > 1) {
    const torch::Tensor dy = (inv_pred.narrow(2, 1, H - 1) - inv_pred.narrow(2, 0, H - 1)).abs();
    tv = tv + masked_mean(dy, mask.defined() ? mask.narrow(2, 1, H - 1) * mask.narrow(2, 0, H - 1) : mask);
  }
  t.tv = tv;
  t.total = w.alpha * hs_term + w.beta * t.depth + w.gamma * t.tv;
  if (depth_logits.defined() && w.ce > 0.0) {
    const torch::Tensor q = two_hot_depth_targets(inv_true.detach(), depth_logits.size(1), w.inv_far, w.inv_near);
    t.ce = masked_mean(-(q * torch::log_softmax(depth_logits, 1)).sum(1, /*keepdim=*/true), mask);
    t.total = t.total + w.ce * t.ce;
  } else {
    t.ce = torch::zeros({}, inv_pred.options());
  }
  return t;
}

}  // namespace hsd::train
