// The fused depth of model.fuse_defocus_reader: the network's depth head and
// the spectral depth-from-defocus reader (defocus_likelihood.h) averaged in
// metres, the reader's costs and the average aggregated edge-aware with the
// guided filter (guided_filter.h) steered by the network's own cube:
//   1. ℓ_k, the reader's cost of layer k with the whitened energy pooled over
//      a reader_box_px box (spectral_defocus_cost_volume);
//   2. ℓ̃_k = GF_g(ℓ_k; r = cost_radius_px), g = fusion_guide(cube);
//   3. z_r = layer_depths_m[argmin_k ℓ̃_k], tied layers
//      at their mean (defocus_layer_depth)           (filtered_reader_depth);
//   4. z = clamp(GF_g(½ (z_net + z_r); r = depth_radius_px),
//               depth_min, depth_max)                  (fuse_depths).
// A radius of 0 leaves its step out (the guided filter is then the identity):
// {31, 0, 0} is the fusion's first form, the plain mean with a 31-px reader.
// A box reader must pool over a wide window to read a layer reliably, which
// blurs depth across objects; the guide, the cube's brightness, marks where
// surfaces meet, so the pooling and the final smoothing stop at its edges.
// The settings were chosen on the quick config's validation scenes and
// checked on its test scenes (docs/learning.md, "The reader's window, and an
// edge-aware aggregation").
#pragma once
#include <vector>

#include <torch/types.h>

namespace hsd::model {

// The defaults are model.fusion_* in configs/base.json.
struct FusionSettings {
  int64_t reader_box_px = 7;    // the reader's energy box (odd) [px]
  int64_t cost_radius_px = 7;   // the guided filter of each layer's cost [px]
  int64_t depth_radius_px = 4;  // the guided filter of the averaged depth [px]
  double guide_eps = 0.1;       // ε in units of the guide's mean squared (> 0)
};

// cube [B, L, H, W] (radiance per band) -> guide [B, 1, H, W]: the mean over
// the bands divided by its mean absolute value over the image (so ε is
// relative; an all-zero cube gives a zero guide, and the filters box means).
torch::Tensor fusion_guide(const torch::Tensor& cube);

// reader_cost [B, K, H, W] (smaller = more likely; any per-pixel offset),
// guide [B, 1, H, W] -> [B, 1, H, W] metres: steps 2 and 3 above (size K of
// layer_depths_m). The cost's dtype is kept.
torch::Tensor filtered_reader_depth(const torch::Tensor& reader_cost, const torch::Tensor& guide,
                                    const std::vector<double>& layer_depths_m, const FusionSettings& s = {});

// network_depth_m, reader_depth_m, guide [B, 1, H, W] (one dtype) -> the fused
// depth [B, 1, H, W] metres within [depth_min_m, depth_max_m]: step 4 above.
torch::Tensor fuse_depths(const torch::Tensor& network_depth_m, const torch::Tensor& reader_depth_m, const torch::Tensor& guide,
                          double depth_min_m, double depth_max_m, const FusionSettings& s = {});

}  // namespace hsd::model
