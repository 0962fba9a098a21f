#include "model/tiled_inference.h"

#include <algorithm>
#include <vector>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::model {

namespace {
// Tile starts covering [0, n) with steps of `tile`.
std::vector<int64_t> starts(int64_t n, int64_t tile) {
  std::vector<int64_t> s;
  for (int64_t v = 0; v < n; v += tile) s.push_back(v);
  return s;
}
// 1-D blending weight over [a − o, b + o) for a core [a, b): ramps of length 2o
// centred on the core's edges (inner edges only), so neighbours sum to one.
torch::Tensor ramp(int64_t lo, int64_t hi, int64_t a, int64_t b, int64_t n, int64_t o) {
  torch::Tensor x = torch::arange(lo, hi, torch::kFloat32) + 0.5f;
  torch::Tensor w = torch::ones({hi - lo});
  if (o > 0) {
    if (a > 0) w = w * ((x - float(a - o)) / float(2 * o)).clamp(0.0, 1.0);
    if (b < n) w = w * ((float(b + o) - x) / float(2 * o)).clamp(0.0, 1.0);
  }
  return w;
}
}  // namespace

std::pair<torch::Tensor, torch::Tensor> tiled_reconstruct(
    const std::function<std::pair<torch::Tensor, torch::Tensor>(const torch::Tensor&)>& f, const torch::Tensor& image,
    int64_t tile, int64_t overlap, const std::function<void(int64_t, int64_t)>& on_tile, int64_t context) {
  if (image.dim() != 3 || image.size(0) != 3) throw InputError("reconstruction input must be [3, H, W]");
  if (tile < 16 || overlap < 0 || 2 * overlap >= tile) throw InputError("tiling: need tile >= 16 and 0 <= 2·overlap < tile");
  if (context < 0) context = 2 * overlap;
  if (context < overlap) throw InputError("tiling: the context must cover the overlap");
  const int64_t H = image.size(1), W = image.size(2);
  const auto ys = starts(H, tile), xs = starts(W, tile);
  torch::Tensor hs, depth;
  torch::Tensor wsum = torch::zeros({1, H, W});
  int64_t done = 0;
  for (int64_t y0 : ys)
    for (int64_t x0 : xs) {
      const int64_t y1 = std::min(H, y0 + tile), x1 = std::min(W, x0 + tile);
      // Context: the blending zone (overlap) plus pixels the network sees but whose outputs are dropped.
      const int64_t cy0 = std::max<int64_t>(0, y0 - context), cy1 = std::min(H, y1 + context);
      const int64_t cx0 = std::max<int64_t>(0, x0 - context), cx1 = std::min(W, x1 + context);
      const auto [h, d] = f(image.narrow(1, cy0, cy1 - cy0).narrow(2, cx0, cx1 - cx0).unsqueeze(0).contiguous());
      if (!hs.defined()) {
        hs = torch::zeros({h.size(1), H, W});
        depth = torch::zeros({1, H, W});
      }
      // Output region written by this tile: the core plus the blending zone.
      const int64_t oy0 = std::max<int64_t>(0, y0 - overlap), oy1 = std::min(H, y1 + overlap);
      const int64_t ox0 = std::max<int64_t>(0, x0 - overlap), ox1 = std::min(W, x1 + overlap);
      const torch::Tensor w = ramp(oy0, oy1, y0, y1, H, overlap).view({1, -1, 1}) * ramp(ox0, ox1, x0, x1, W, overlap).view({1, 1, -1});
      auto region = [&](const torch::Tensor& t) { return t[0].narrow(1, oy0 - cy0, oy1 - oy0).narrow(2, ox0 - cx0, ox1 - ox0).cpu().to(torch::kFloat32); };
      // accumulated in place (a [L, h, w] product would be a 30+ MB temporary per tile)
      hs.narrow(1, oy0, oy1 - oy0).narrow(2, ox0, ox1 - ox0).addcmul_(region(h), w);
      depth.narrow(1, oy0, oy1 - oy0).narrow(2, ox0, ox1 - ox0).addcmul_(region(d), w);
      wsum.narrow(1, oy0, oy1 - oy0).narrow(2, ox0, ox1 - ox0).add_(w);
      if (on_tile) on_tile(++done, int64_t(ys.size() * xs.size()));
    }
  const torch::Tensor inv = 1.0 / wsum.clamp_min(1e-12);
  hs.mul_(inv);
  depth.mul_(inv);
  return {hs, depth};
}

}  // namespace hsd::model
