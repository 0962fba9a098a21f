#include "optics/depth_distinctness.h"

#include <algorithm>
#include <limits>

#include <torch/torch.h>

#include "common/error.h"
#include "common/fft_size.h"

namespace hsd::optics {

DepthDistinctness depth_distinctness(const torch::Tensor& psf) {
  if (psf.dim() != 4 || psf.size(1) < 2) throw InputError("depth distinctness: needs a PSF stack [L, Z >= 2, P, P]");
  const torch::Tensor p = psf.detach().to(torch::kFloat64).cpu();
  DepthDistinctness d;
  for (int64_t l = 0; l < p.size(0); ++l) {
    double best = std::numeric_limits<double>::infinity();
    std::pair<int64_t, int64_t> at{0, 1};
    for (int64_t a = 0; a < p.size(1); ++a)
      for (int64_t b = a + 1; b < p.size(1); ++b) {
        const double tv = 0.5 * (p[l][a] - p[l][b]).abs().sum().item<double>();
        if (tv < best) best = tv, at = {a, b};
      }
    d.per_band.push_back(best);
    d.pair.push_back(at);
  }
  return d;
}

int64_t scene_dft_size(int64_t psf_px) { return std::max<int64_t>(128, fast_fft_size(2 * psf_px)); }

torch::Tensor psf_mtf2(const torch::Tensor& psf, int64_t n) {
  const int64_t P = psf.size(-1);
  const torch::Tensor H = torch::fft::fft2(torch::constant_pad_nd(psf, {0, n - P, 0, n - P}));
  return torch::real(H).square() + torch::imag(H).square();
}

torch::Tensor natural_texture_spectrum(int64_t n, double corner_cycles_per_px, c10::ScalarType dtype) {
  const torch::Tensor f = torch::fft::fftfreq(n, dtype);
  const torch::Tensor S =
      1.0 / (f.view({-1, 1}).square() + f.view({1, -1}).square() + corner_cycles_per_px * corner_cycles_per_px);
  return S / S.mean();
}

SceneDepthCue scene_depth_cue(const torch::Tensor& psf, double noise_variance, double corner_cycles_per_px) {
  if (psf.dim() != 4 || psf.size(1) < 2 || psf.size(2) != psf.size(3))
    throw InputError("scene depth cue: needs a PSF stack [L, Z >= 2, P, P]");
  if (!(noise_variance > 0) || !(corner_cycles_per_px > 0))
    throw InputError("scene depth cue: the noise variance and the corner frequency must be > 0");
  const int64_t N = scene_dft_size(psf.size(2));
  const torch::Tensor p = psf.detach().to(torch::kFloat64).cpu();
  const torch::Tensor S = natural_texture_spectrum(N, corner_cycles_per_px, torch::kFloat64);
  const torch::Tensor power = S * psf_mtf2(p, N) + noise_variance;  // [L, Z, N, N], > 0
  SceneDepthCue cue;
  for (int64_t l = 0; l < p.size(0); ++l) {
    double best = std::numeric_limits<double>::infinity(), sum = 0.0;
    int64_t n = 0;
    std::pair<int64_t, int64_t> at{0, 1};
    for (int64_t a = 0; a < p.size(1); ++a)
      for (int64_t b = a + 1; b < p.size(1); ++b) {
        const torch::Tensor& Pa = power[l][a];
        const torch::Tensor& Pb = power[l][b];
        const double d = (0.5 * (Pa - Pb).square() / (Pa * Pb)).mean().item<double>();
        if (d < best) best = d, at = {a, b};
        sum += d, ++n;
      }
    cue.min_per_slice.push_back(best);
    cue.mean_per_slice.push_back(sum / double(n));
    cue.pair.push_back(at);
  }
  return cue;
}

}  // namespace hsd::optics
