#include "optics/synthetic_captures.h"

#include <torch/torch.h>

#include "optics/psf_calibration.h"

namespace hsd::optics {

SyntheticCaptures synthesize_captures(const torch::Tensor& psf_frames, const SyntheticCaptureConfig& cfg, uint64_t seed) {
  const int64_t L = psf_frames.size(0), Z = psf_frames.size(1), F = psf_frames.size(2);
  auto gen = at::detail::createCPUGenerator(seed);
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
  SyntheticCaptures out;
  const double dy = cfg.axis_offset_px[0], dx = cfg.axis_offset_px[1];
  out.axis_px = {double(F / 2) + dy, double(F / 2) + dx};
  // Hot pixels: fixed positions and dark currents.
  out.hot = torch::zeros({F * F}, torch::kBool);
  torch::Tensor hot_level = torch::zeros({F * F}, f64);
  if (cfg.hot_pixels > 0) {
    const torch::Tensor idx = torch::randperm(F * F, gen, torch::TensorOptions().dtype(torch::kInt64)).narrow(0, 0, std::min(cfg.hot_pixels, F * F));
    out.hot.index_fill_(0, idx, true);
    hot_level.index_copy_(0, idx, 2000.0 + 18000.0 * at::rand({idx.numel()}, gen, f64));
  }
  out.hot = out.hot.view({F, F});
  hot_level = hot_level.view({F, F});
  auto record = [&](const torch::Tensor& light) {
    torch::Tensor v = at::poisson(light + cfg.background_counts, gen) + at::poisson(hot_level, gen) + cfg.dark_counts;
    v = v + cfg.read_noise_counts * at::normal(0.0, 1.0, {F, F}, gen, f64);
    return v.round().clamp(0.0, 65535.0);
  };
  const int64_t E = cfg.exposures;
  out.frames = torch::empty({L, Z, E, F, F}, f64);
  for (int64_t l = 0; l < L; ++l)
    for (int64_t z = 0; z < Z; ++z) {
      torch::Tensor p = fourier_shift(psf_frames[l][z].to(torch::kFloat64), dy, dx).clamp_min(0.0);
      p = p * (cfg.peak_counts / std::max(1e-300, p.max().item<double>()));
      for (int64_t e = 0; e < E; ++e) out.frames[l][z][e].copy_(record(p));
    }
  // The dark frames: the source off (stray light, dark current, read noise).
  out.dark = torch::empty({E, F, F}, f64);
  for (int64_t e = 0; e < E; ++e) {
    const torch::Tensor d = at::poisson(torch::full({F, F}, cfg.background_counts, f64), gen) + at::poisson(hot_level, gen) +
                            cfg.dark_counts + cfg.read_noise_counts * at::normal(0.0, 1.0, {F, F}, gen, f64);
    out.dark[e].copy_(d.round().clamp(0.0, 65535.0));
  }
  return out;
}

}  // namespace hsd::optics
