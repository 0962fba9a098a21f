#include "train/baselines.h"

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

}  // namespace hsd::train
