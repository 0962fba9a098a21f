#include "train/baselines.h"

#include <cmath>
#include <limits>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::train {

double median_inverse_depth(const std::vector<data::LoadedScene>& scenes) {
  std::vector<torch::Tensor> inv;
  for (const auto& s : scenes) {
    const torch::Tensor z = s.scene.depth_m.to(torch::kFloat64).flatten();
    const torch::Tensor valid = (s.scene.mask.flatten() > 0.5) & torch::isfinite(z) & (z > 0);
    inv.push_back(1.0 / z.masked_select(valid));
  }
  const torch::Tensor all = inv.empty() ? torch::empty({0}, torch::kFloat64) : torch::cat(inv);
  if (all.numel() == 0) throw InputError("constant-depth baseline: the training split has no valid depth pixel");
  // The lower median (torch's convention), exact for any count.
  return all.median().item<double>();
}

torch::Tensor constant_depth_map(const torch::Tensor& like, double inv_depth_per_m) {
  if (!(inv_depth_per_m > 0)) throw InputError("constant-depth baseline: the inverse depth must be > 0");
  return torch::full_like(like, 1.0 / inv_depth_per_m);
}

torch::Tensor box_oracle_depth_map(const torch::Tensor& depth_m, const torch::Tensor& mask, int64_t window_px) {
  if (window_px < 1 || window_px % 2 == 0) throw InputError("resolution oracle: the window must be odd and >= 1");
  if (depth_m.dim() < 2 || !mask.sizes().equals(depth_m.sizes()))
    throw InputError("resolution oracle: depth and mask must be [.., H, W] of the same shape, got " +
                     c10::str(depth_m.sizes()) + " and " + c10::str(mask.sizes()));
  const int64_t H = depth_m.size(-2), W = depth_m.size(-1), w = window_px;
  const torch::Tensor z = depth_m.to(torch::kFloat64).reshape({-1, 1, H, W});
  const torch::Tensor v = ((mask.reshape({-1, 1, H, W}) > 0.5) & torch::isfinite(z) & (z > 0)).to(torch::kFloat64);
  const torch::Tensor inv = torch::where(v > 0, 1.0 / z, torch::zeros_like(z));
  // Box sums as two 1-D sums (zero padding: the box is clipped at the borders).
  namespace F = torch::nn::functional;
  auto box = [&](const torch::Tensor& x) {
    torch::Tensor y = F::avg_pool2d(x, F::AvgPool2dFuncOptions({w, 1}).stride(1).padding({w / 2, 0}).count_include_pad(true));
    return F::avg_pool2d(y, F::AvgPool2dFuncOptions({1, w}).stride(1).padding({0, w / 2}).count_include_pad(true));
  };
  const torch::Tensor num = box(inv), den = box(v);
  const torch::Tensor est = torch::where(den > 1e-12, den / num.clamp_min(1e-300), z);
  return est.reshape(depth_m.sizes()).to(depth_m.scalar_type());
}

double effective_resolution_px(const std::vector<int64_t>& windows, const std::vector<double>& oracle_rmse, double rmse) {
  if (windows.empty() || windows.size() != oracle_rmse.size())
    throw InputError("effective resolution: windows and oracle RMSEs must be non-empty and of equal size");
  if (rmse <= oracle_rmse.front()) return double(windows.front());
  for (size_t i = 1; i < windows.size(); ++i)
    if (rmse <= oracle_rmse[i]) {
      const double a = oracle_rmse[i - 1], b = oracle_rmse[i];
      const double t = b > a ? (rmse - a) / (b - a) : 1.0;
      return std::exp(std::log(double(windows[i - 1])) + t * (std::log(double(windows[i])) - std::log(double(windows[i - 1]))));
    }
  return std::numeric_limits<double>::infinity();
}

}  // namespace hsd::train
