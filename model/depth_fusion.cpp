#include "model/depth_fusion.h"

#include <torch/torch.h>

#include "common/error.h"
#include "model/defocus_likelihood.h"
#include "model/guided_filter.h"

namespace hsd::model {

torch::Tensor fusion_guide(const torch::Tensor& cube) {
  if (cube.dim() != 4) throw InputError("fusion_guide: the cube must be [B, L, H, W], got " + c10::str(cube.sizes()));
  const torch::Tensor g = cube.mean(1, true);
  return g / g.abs().mean({2, 3}, true).clamp_min(1e-12);
}

torch::Tensor filtered_reader_depth(const torch::Tensor& reader_cost, const torch::Tensor& guide,
                                    const std::vector<double>& layer_depths_m, const FusionSettings& s) {
  const torch::Tensor c = guided_filter(guide.to(reader_cost.scalar_type()), reader_cost, s.cost_radius_px, s.guide_eps);
  return defocus_layer_depth(c, layer_depths_m).unsqueeze(1);
}

torch::Tensor fuse_depths(const torch::Tensor& network_depth_m, const torch::Tensor& reader_depth_m, const torch::Tensor& guide,
                          double depth_min_m, double depth_max_m, const FusionSettings& s) {
  if (network_depth_m.sizes() != reader_depth_m.sizes() || network_depth_m.dim() != 4 || network_depth_m.size(1) != 1)
    throw InputError("fuse_depths: both depths must be [B, 1, H, W], got " + c10::str(network_depth_m.sizes()) + " and " +
                     c10::str(reader_depth_m.sizes()));
  if (!(depth_min_m > 0) || !(depth_max_m > depth_min_m))
    throw InputError("fuse_depths: the depth range must be 0 < min < max, got " + c10::str(depth_min_m) + " and " +
                     c10::str(depth_max_m));
  const torch::Tensor mean = 0.5 * (network_depth_m + reader_depth_m.to(network_depth_m.scalar_type()));
  return guided_filter(guide.to(mean.scalar_type()), mean, s.depth_radius_px, s.guide_eps).clamp(depth_min_m, depth_max_m);
}

}  // namespace hsd::model
