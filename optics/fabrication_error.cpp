#include "optics/fabrication_error.h"

#include <cmath>

#include <torch/torch.h>

namespace hsd::optics {

torch::Tensor gaussian_blur_2d(const torch::Tensor& map, double sigma_samples) {
  if (!(sigma_samples > 0.0)) return map;
  const int64_t r = std::max<int64_t>(1, int64_t(std::ceil(4.0 * sigma_samples)));
  torch::Tensor k = torch::arange(-r, r + 1, torch::TensorOptions().dtype(torch::kFloat64));
  k = torch::exp(-0.5 * (k / sigma_samples).pow(2));
  k = (k / k.sum()).to(map.scalar_type()).to(map.device());
  namespace F = torch::nn::functional;
  torch::Tensor x = map.unsqueeze(0).unsqueeze(0);
  x = F::pad(x, F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate));
  x = F::conv2d(x, k.view({1, 1, 1, -1}));
  x = F::conv2d(x, k.view({1, 1, -1, 1}));
  return x[0][0];
}

torch::Tensor apply_fabrication_error(const torch::Tensor& height_m, const FabricationErrorConfig& err, double doe_pitch_m,
                                      uint64_t seed) {
  torch::Tensor h = height_m.to(torch::kFloat64);
  h = gaussian_blur_2d(h, err.edge_blur_m / doe_pitch_m);
  h = h * (1.0 + err.height_scale_error);
  if (err.roughness_rms_m > 0.0) {
    auto gen = at::detail::createCPUGenerator(seed);
    torch::Tensor r = at::normal(0.0, 1.0, h.sizes(), gen, torch::TensorOptions().dtype(torch::kFloat64));
    r = gaussian_blur_2d(r, err.roughness_correlation_m / doe_pitch_m);
    const double rms = r.pow(2).mean().sqrt().item<double>();
    h = h + (r * (err.roughness_rms_m / std::max(rms, 1e-300))).to(h.device());
  }
  return h.clamp_min(0.0).to(height_m.scalar_type());
}

}  // namespace hsd::optics
