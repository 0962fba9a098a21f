#include "model/guided_filter.h"

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::model {

namespace F = torch::nn::functional;

torch::Tensor box_mean(const torch::Tensor& x, int64_t radius_px) {
  if (x.dim() != 4 || radius_px < 0)
    throw InputError("box_mean: x must be [B, C, H, W] and the radius >= 0, got " + c10::str(x.sizes()) + " and " +
                     std::to_string(radius_px));
  if (radius_px == 0) return x;
  return F::avg_pool2d(x, F::AvgPool2dFuncOptions(2 * radius_px + 1).stride(1).padding(radius_px).count_include_pad(false));
}

torch::Tensor guided_filter(const torch::Tensor& guide, const torch::Tensor& input, int64_t radius_px, double eps) {
  if (guide.dim() != 4 || input.dim() != 4 || guide.size(1) != 1 || guide.size(0) != input.size(0) ||
      guide.size(2) != input.size(2) || guide.size(3) != input.size(3) || guide.scalar_type() != input.scalar_type())
    throw InputError("guided_filter: guide must be [B, 1, H, W] and input [B, K, H, W] of one dtype, got " +
                     c10::str(guide.sizes()) + " and " + c10::str(input.sizes()));
  if (radius_px < 0 || !(eps > 0))
    throw InputError("guided_filter: the radius must be >= 0 and eps > 0, got " + std::to_string(radius_px) + " and " +
                     c10::str(eps));
  const torch::Tensor mI = box_mean(guide, radius_px), mp = box_mean(input, radius_px);
  // clamp: E[I²] − E[I]² may round below zero on a flat guide.
  const torch::Tensor var = (box_mean(guide * guide, radius_px) - mI * mI).clamp_min(0.0);
  const torch::Tensor cov = box_mean(guide * input, radius_px) - mI * mp;
  const torch::Tensor a = cov / (var + eps);
  const torch::Tensor b = mp - a * mI;
  return box_mean(a, radius_px) * guide + box_mean(b, radius_px);
}

}  // namespace hsd::model
