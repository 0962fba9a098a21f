#include "model/defocus_likelihood.h"

#include <torch/torch.h>

#include "common/error.h"
#include "common/fft_size.h"

namespace hsd::model {

namespace F = torch::nn::functional;

namespace {

// S(f) ∝ 1/(|f|² + f₀²) on the DFT grid [nh, nw] (full) or its real half
// [nh, nw/2+1], normalised to mean 1 over the full grid.
torch::Tensor texture_spectrum(int64_t nh, int64_t nw, double f0, bool half, c10::ScalarType dtype) {
  const auto opt = torch::TensorOptions().dtype(dtype);
  const torch::Tensor fy = torch::fft::fftfreq(nh, opt).view({-1, 1});
  const torch::Tensor full = 1.0 / (fy.square() + torch::fft::fftfreq(nw, opt).view({1, -1}).square() + f0 * f0);
  if (!half) return full / full.mean();
  const torch::Tensor h = 1.0 / (fy.square() + torch::fft::rfftfreq(nw, opt).view({1, -1}).square() + f0 * f0);
  return h / full.mean();
}

}  // namespace

torch::Tensor defocus_cost_volume(const torch::Tensor& image, const torch::Tensor& rgb_psf, const DefocusModel& m) {
  if (image.dim() != 4 || rgb_psf.dim() != 4 || rgb_psf.size(1) != image.size(1) || rgb_psf.size(2) != rgb_psf.size(3) ||
      rgb_psf.size(2) % 2 == 0)
    throw InputError("defocus_cost_volume: image must be [B, C, H, W] and psf [K, C, P, P] with P odd, got " +
                     c10::str(image.sizes()) + " and " + c10::str(rgb_psf.sizes()));
  if (!(m.noise_ratio > 0) || !(m.corner_cycles_per_px > 0) || m.window_px < 1 || m.window_px % 2 == 0)
    throw InputError("defocus_cost_volume: the noise ratio and corner frequency must be > 0 and the window odd and >= 1");
  const int64_t B = image.size(0), C = image.size(1), H = image.size(2), W = image.size(3);
  const int64_t K = rgb_psf.size(0), P = rgb_psf.size(2), r = P / 2;
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r);
  const auto dtype = image.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  const torch::Tensor x = F::pad(image.to(dtype), F::PadFuncOptions({r, nw - W - r, r, nh - H - r}).mode(torch::kReplicate));
  torch::Tensor k = F::pad(rgb_psf.to(dtype), F::PadFuncOptions({0, nw - P, 0, nh - P}));
  k = torch::roll(k, {-r, -r}, {2, 3});  // the PSF's centre at (0, 0)
  // D on the real half grid for the whitening, on the full grid for the log-determinant's mean.
  const torch::Tensor Hh = torch::fft::rfft2(k), Hfull = torch::fft::fft2(k);
  const torch::Tensor Dh = texture_spectrum(nh, nw, m.corner_cycles_per_px, true, dtype) *
                               (torch::real(Hh).square() + torch::imag(Hh).square()) + m.noise_ratio;  // [K, C, nh, nw/2+1]
  const torch::Tensor Dfull = texture_spectrum(nh, nw, m.corner_cycles_per_px, false, dtype) *
                                  (torch::real(Hfull).square() + torch::imag(Hfull).square()) + m.noise_ratio;
  const torch::Tensor logdet = torch::log(Dfull).mean({2, 3});                  // [K, C]
  const torch::Tensor Y = torch::fft::rfft2(x).unsqueeze(1);                     // [B, 1, C, nh, nw/2+1]
  const torch::Tensor w = torch::fft::irfft2(Y * torch::rsqrt(Dh).unsqueeze(0), c10::IntArrayRef{nh, nw});  // [B, K, C, nh, nw]
  // Local energy: the mean of |w|² over the box (reflect-free: the extension already surrounds the image).
  const int64_t h = m.window_px / 2;
  torch::Tensor e = w.narrow(3, r - std::min(r, h), H + 2 * std::min(r, h)).narrow(4, r - std::min(r, h), W + 2 * std::min(r, h)).square();
  e = e.reshape({B * K * C, 1, e.size(3), e.size(4)});
  e = F::avg_pool2d(e, F::AvgPool2dFuncOptions(m.window_px).stride(1).padding(std::max<int64_t>(0, h - std::min(r, h)))
                           .count_include_pad(false));
  e = e.reshape({B, K, C, H, W});
  // A floor far below any real image's energy keeps the log finite on a black region.
  const torch::Tensor cost = torch::log(e + 1e-20) + logdet.view({1, K, C, 1, 1});
  return cost.sum(2);
}

torch::Tensor defocus_layer_depth(const torch::Tensor& cost, const std::vector<double>& layer_depths_m) {
  if (cost.dim() != 4 || cost.size(1) != int64_t(layer_depths_m.size()))
    throw InputError("defocus_layer_depth: cost must be [B, K, H, W] with K = " + std::to_string(layer_depths_m.size()) +
                     " layers, got " + c10::str(cost.sizes()));
  const torch::Tensor z = torch::tensor(layer_depths_m, torch::TensorOptions().dtype(torch::kFloat64)).to(cost.dtype());
  return z.index({cost.argmin(1)});
}

}  // namespace hsd::model
