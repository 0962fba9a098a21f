#include "model/defocus_likelihood.h"

#include <torch/torch.h>

#include "common/error.h"
#include "common/fft_size.h"
#include "model/wiener_preinverse.h"

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

// The mean over a window_px box around each of the H × W image pixels of a
// field [N, nh, nw] laid out as the image extended by r pixels on the top and
// left (the readers' FFT grid): the extension stands in for the scene up to r
// pixels out, zero padding counted out beyond -> [N, 1, H, W].
torch::Tensor local_mean(const torch::Tensor& field, int64_t r, int64_t H, int64_t W, int64_t window_px) {
  const int64_t h = window_px / 2, m = std::min(r, h);
  const torch::Tensor e = field.narrow(1, r - m, H + 2 * m).narrow(2, r - m, W + 2 * m).unsqueeze(1);
  return F::avg_pool2d(e, F::AvgPool2dFuncOptions(window_px).stride(1).padding(h - m).count_include_pad(false));
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
  const torch::Tensor k = centred_padded_psf(rgb_psf.to(dtype), nh, nw);
  // D on the real half grid for the whitening, on the full grid for the log-determinant's mean.
  const torch::Tensor Hh = torch::fft::rfft2(k), Hfull = torch::fft::fft2(k);
  const torch::Tensor Dh = texture_spectrum(nh, nw, m.corner_cycles_per_px, true, dtype) *
                               (torch::real(Hh).square() + torch::imag(Hh).square()) + m.noise_ratio;  // [K, C, nh, nw/2+1]
  const torch::Tensor Dfull = texture_spectrum(nh, nw, m.corner_cycles_per_px, false, dtype) *
                                  (torch::real(Hfull).square() + torch::imag(Hfull).square()) + m.noise_ratio;
  const torch::Tensor logdet = torch::log(Dfull).mean({2, 3});                  // [K, C]
  const torch::Tensor Y = torch::fft::rfft2(x).unsqueeze(1);                     // [B, 1, C, nh, nw/2+1]
  const torch::Tensor w = torch::fft::irfft2(Y * torch::rsqrt(Dh).unsqueeze(0), c10::IntArrayRef{nh, nw});  // [B, K, C, nh, nw]
  // Local energy: the mean of |w|² over the box.
  const torch::Tensor e = local_mean(w.square().reshape({B * K * C, nh, nw}), r, H, W, m.window_px).reshape({B, K, C, H, W});
  // A floor far below any real image's energy keeps the log finite on a black region.
  const torch::Tensor cost = torch::log(e + 1e-20) + logdet.view({1, K, C, 1, 1});
  return cost.sum(2);
}

torch::Tensor spectral_defocus_cost_volume(const torch::Tensor& image, const torch::Tensor& psf, const torch::Tensor& omega,
                                           const SpectralPrior& prior, int64_t window_px) {
  check_spectral_inputs("spectral_defocus_cost_volume", image, psf, omega, prior);
  const int64_t L = psf.size(0), K = psf.size(1), P = psf.size(2), r = P / 2;
  if (window_px < 1 || window_px % 2 == 0) throw InputError("spectral_defocus_cost_volume: the window must be odd and >= 1");
  // The image is the only input a gradient reaches: the PSFs, the camera and
  // the prior enter as constants (the log-determinant is a number).
  const int64_t B = image.size(0), H = image.size(2), W = image.size(3);
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r), nf = nw / 2 + 1, F_ = nh * nf;
  const auto dtype = image.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(image.device());
  const torch::Tensor Om = omega.detach().to(f64), mu = prior.mean.detach().to(f64).reshape({L});
  // Σ = V Vᵀ, so H Σ Hᴴ = Q Qᴴ with Q = Ω diag(K) V [3, R] (spectral_wiener_factor's rows Ω_cλ V_λj).
  const torch::Tensor Vq = spectral_wiener_factor(Om, prior.covariance.detach().to(f64));  // [3R, L]
  const int64_t R = Vq.size(0) / 3;
  // Band OTFs with the PSF's centre at (0, 0): [L, K, F].
  const torch::Tensor Kf = torch::fft::rfft2(centred_padded_psf(psf.detach().to(f64), nh, nw)).reshape({L, K, F_});
  const torch::Tensor S = spectral_wiener_psd(nh, nw, prior.psd_exponent, image.device());  // [F]
  const double s2 = prior.noise_var;
  // Full-grid means from the real half: its columns 1 .. ceil(nw/2) − 1 stand for two.
  torch::Tensor wcol = torch::full({nf}, 2.0, f64);
  wcol[0] = 1.0;
  if (nw % 2 == 0) wcol[nf - 1] = 1.0;
  const torch::Tensor wf = wcol.repeat({nh}) / double(nh * nw);  // [F]
  torch::Tensor y = image.to(f64) - torch::matmul(Om, mu).view({1, 3, 1, 1});
  y = F::pad(y, F::PadFuncOptions({r, nw - W - r, r, nh - H - r}).mode(torch::kReplicate));
  const torch::Tensor Y = torch::fft::rfft2(y).reshape({B, 3, F_});
  const torch::Tensor Y0 = Y.select(1, 0), Y1 = Y.select(1, 1), Y2 = Y.select(1, 2);
  std::vector<torch::Tensor> costs;
  for (int64_t z = 0; z < K; ++z) {  // one layer at a time: Q is [3, R, F]
    const torch::Tensor kc = torch::view_as_real(Kf.select(1, z).contiguous()).reshape({L, F_ * 2});
    const torch::Tensor q = torch::view_as_complex(torch::matmul(Vq, kc).view({3, R, F_, 2}));
    auto sq = [&](int64_t c) { return torch::real(q[c] * q[c].conj()).sum(0); };
    auto cross = [&](int64_t c, int64_t d) { return (q[c] * q[d].conj()).sum(0); };  // M_cd / S
    // M = S Q Qᴴ + σ² I = L Lᴴ, Cholesky by hand per frequency (lower; diagonals real and > 0).
    const torch::Tensor m00 = S * sq(0) + s2, m11 = S * sq(1) + s2, m22 = S * sq(2) + s2;
    const torch::Tensor m10 = S * cross(1, 0), m20 = S * cross(2, 0), m21 = S * cross(2, 1);
    const torch::Tensor l00 = m00.sqrt();
    const torch::Tensor l10 = m10 / l00, l20 = m20 / l00;
    const torch::Tensor l11 = (m11 - torch::real(l10 * l10.conj())).clamp_min(1e-300).sqrt();
    const torch::Tensor l21 = (m21 - l20 * l10.conj()) / l11;
    const torch::Tensor l22 = (m22 - torch::real(l20 * l20.conj()) - torch::real(l21 * l21.conj())).clamp_min(1e-300).sqrt();
    const double logdet = (2.0 * (l00.log() + l11.log() + l22.log()) * wf).sum().item<double>();
    // Whitened by L⁻¹ (forward substitution): |L⁻¹ Y|² = Yᴴ M⁻¹ Y at every frequency.
    const torch::Tensor w0 = Y0 / l00, w1 = (Y1 - l10 * w0) / l11, w2 = (Y2 - l20 * w0 - l21 * w1) / l22;
    const torch::Tensor w = torch::fft::irfft2(torch::stack({w0, w1, w2}, 1).reshape({B, 3, nh, nf}), c10::IntArrayRef{nh, nw});
    const torch::Tensor en = local_mean(w.square().sum(1), r, H, W, window_px);  // [B, 1, H, W]
    costs.push_back(3.0 * torch::log(en / 3.0 + 1e-300) + logdet);
  }
  return torch::cat(costs, 1).to(dtype);  // [B, K, H, W]
}

torch::Tensor defocus_layer_depth(const torch::Tensor& cost, const std::vector<double>& layer_depths_m) {
  if (cost.dim() != 4 || cost.size(1) != int64_t(layer_depths_m.size()))
    throw InputError("defocus_layer_depth: cost must be [B, K, H, W] with K = " + std::to_string(layer_depths_m.size()) +
                     " layers, got " + c10::str(cost.sizes()));
  const torch::Tensor z =
      torch::tensor(layer_depths_m, torch::TensorOptions().dtype(torch::kFloat64)).to(cost.dtype()).view({1, -1, 1, 1});
  // Every layer within kLayerTieNats of the least cost, averaged (exactly
  // layer_depths_m[argmin] where one layer is least: z·1 / 1).
  const torch::Tensor least = std::get<0>(cost.min(1, /*keepdim=*/true));
  const torch::Tensor tie = (cost <= least + kLayerTieNats).to(cost.dtype());
  return (tie * z).sum(1) / tie.sum(1);
}

}  // namespace hsd::model
