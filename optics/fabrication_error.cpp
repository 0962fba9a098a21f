#include "optics/fabrication_error.h"

#include <cmath>
#include <stdexcept>

#include <torch/torch.h>

#include "optics/lithography.h"

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

torch::Tensor refine_cells(const torch::Tensor& map, int64_t s) {
  if (s == 1) return map;
  return map.repeat_interleave(s, 0).repeat_interleave(s, 1);
}

namespace {
// Whole-sample shift along `dim` (0 rows, 1 columns) by n, zeros moving in:
// padding and a slice, so autograd passes through.
torch::Tensor shift_whole(const torch::Tensor& m, int64_t n, int64_t dim) {
  const int64_t len = m.size(dim);
  if (n == 0) return m;
  if (std::llabs(n) >= len) return torch::zeros_like(m);
  namespace F = torch::nn::functional;
  const int64_t a = std::llabs(n);
  // F::pad takes (left, right, top, bottom) for the last two axes.
  std::vector<int64_t> pad = dim == 1 ? std::vector<int64_t>{a, a, 0, 0} : std::vector<int64_t>{0, 0, a, a};
  const torch::Tensor p = F::pad(m.unsqueeze(0), F::PadFuncOptions(pad))[0];
  return p.narrow(dim, n > 0 ? 0 : 2 * a, len);
}
torch::Tensor shift_axis(const torch::Tensor& m, double d, int64_t dim) {
  if (d == 0.0) return m;
  const double fl = std::floor(d);
  const double f = d - fl;
  const torch::Tensor a = shift_whole(m, int64_t(fl), dim);
  if (f < 1e-12) return a;
  return a * (1.0 - f) + shift_whole(m, int64_t(fl) + 1, dim) * f;
}
}  // namespace

torch::Tensor shift_map(const torch::Tensor& map, double dy_samples, double dx_samples) {
  return shift_axis(shift_axis(map, dx_samples, 1), dy_samples, 0);
}

torch::Tensor fabricated_surface(const torch::Tensor& height_m, const FabricationErrorConfig& err,
                                 const FabricationProcess& p, uint64_t seed) {
  const int64_t s = p.subsamples;
  const double sub = p.pitch_m / double(s);  // sub-cell pitch
  torch::Tensor h;
  if (err.misalignment_m > 0.0) {
    if (p.levels < 2 || !(p.max_height_m > 0.0))
      throw std::invalid_argument("a mask misalignment needs the lithography's levels and maximum height");
    const LevelMap q = quantize_to_levels(height_m, p.max_height_m, p.levels);
    const torch::Tensor masks = level_masks(q).to(torch::kFloat64);
    h = torch::zeros({height_m.size(0) * s, height_m.size(1) * s}, torch::kFloat64);
    for (int64_t k = 0; k < masks.size(0); ++k) {
      torch::Tensor mk = refine_cells(masks[k], s);
      if (k >= 1) {
        const double th = M_PI / 4.0 + double(k - 1) * M_PI / 2.0;
        mk = shift_map(mk, err.misalignment_m * std::sin(th) / sub, err.misalignment_m * std::cos(th) / sub);
      }
      h = h + mk * (double(int64_t(1) << k) * q.step_m);
    }
    h = h.to(height_m.device());
  } else {
    h = refine_cells(height_m.to(torch::kFloat64), s);  // differentiable in height_m
  }
  if (err.decentre_m > 0.0)
    h = shift_map(h, err.decentre_m * std::sin(p.decentre_angle_rad) / sub, err.decentre_m * std::cos(p.decentre_angle_rad) / sub);
  h = gaussian_blur_2d(h, err.edge_blur_m / sub);
  h = h * (1.0 + err.height_scale_error);
  if (err.roughness_rms_m > 0.0) {
    auto gen = at::detail::createCPUGenerator(seed);
    torch::Tensor r = at::normal(0.0, 1.0, height_m.sizes(), gen, torch::TensorOptions().dtype(torch::kFloat64));
    r = gaussian_blur_2d(refine_cells(r, s), err.roughness_correlation_m / sub);
    const double rms = r.pow(2).mean().sqrt().item<double>();
    h = h + (r * (err.roughness_rms_m / std::max(rms, 1e-300))).to(h.device());
  }
  return h.clamp_min(0.0).to(height_m.scalar_type()).to(height_m.device());
}

torch::Tensor apply_fabrication_error(const torch::Tensor& height_m, const FabricationErrorConfig& err,
                                      const FabricationProcess& process, uint64_t seed) {
  FabricationProcess p = process;
  p.subsamples = 1;
  return fabricated_surface(height_m, err, p, seed);
}

FabricationErrorConfig draw_fabrication_error(const FabricationErrorConfig& scales, std::mt19937_64& rng, double* angle_rad) {
  FabricationErrorConfig e;
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  e.height_scale_error = std::clamp(scales.height_scale_error * normal(rng), -0.45, 0.45);
  e.roughness_rms_m = scales.roughness_rms_m;
  e.roughness_correlation_m = scales.roughness_correlation_m;
  e.edge_blur_m = scales.edge_blur_m * unit(rng);
  e.decentre_m = scales.decentre_m * unit(rng);
  const double a = 2.0 * M_PI * unit(rng);
  if (angle_rad) *angle_rad = a;
  return e;
}

FabricationErrorConfig scaled_fabrication_error(FabricationErrorConfig e, double f) {
  e.height_scale_error *= f, e.roughness_rms_m *= f, e.edge_blur_m *= f, e.misalignment_m *= f, e.decentre_m *= f;
  return e;
}

bool no_fabrication_error(const FabricationErrorConfig& e) {
  return e.height_scale_error == 0.0 && e.roughness_rms_m == 0.0 && e.edge_blur_m == 0.0 && e.misalignment_m == 0.0 &&
         e.decentre_m == 0.0;
}

}  // namespace hsd::optics
