#include "optics/aperture.h"

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {

torch::Tensor centred_coordinates(int64_t n, double pitch_m) {
  return (torch::arange(n, torch::kFloat64) - 0.5 * double(n - 1)) * pitch_m;
}

torch::Tensor aperture_transmission(int64_t n, double pitch_m, double diameter_m, const std::string& shape) {
  const int64_t ss = 8;
  // sub-sample coordinates: cell j spans [x_j − δ/2, x_j + δ/2]
  const torch::Tensor sub = (torch::arange(n * ss, torch::kFloat64) + 0.5) / double(ss) - 0.5 * double(n);
  const torch::Tensor x = sub * pitch_m;  // [N·ss]
  const double r = 0.5 * diameter_m;
  if (shape == "square") {
    const torch::Tensor inside = (x.abs() <= r).to(torch::kFloat64).view({n, ss}).mean(1);  // [N]
    return torch::outer(inside, inside);
  }
  if (shape != "circle") input_error("config key optics.aperture_shape", "unknown shape \"" + shape + "\"");
  const torch::Tensor r2 = x.view({-1, 1}).pow(2) + x.view({1, -1}).pow(2);
  const torch::Tensor inside = (r2 <= r * r).to(torch::kFloat64).view({1, 1, n * ss, n * ss});
  return torch::avg_pool2d(inside, {ss, ss}).view({n, n});
}

}  // namespace hsd::optics
