#include "model/wiener_preinverse.h"

#include <torch/torch.h>

#include "common/error.h"
#include "common/fft_size.h"

namespace hsd::model {

namespace F = torch::nn::functional;

torch::Tensor camera_rgb_psfs(const torch::Tensor& psf, const torch::Tensor& omega) {
  if (psf.dim() != 4 || omega.dim() != 2 || omega.size(1) != psf.size(0))
    throw InputError("camera_rgb_psfs: psf must be [L, K, P, P] and omega [C, L], got " + c10::str(psf.sizes()) +
                     " and " + c10::str(omega.sizes()));
  const torch::Tensor w = omega.to(psf.dtype());
  const torch::Tensor num = torch::einsum("cl,lkpq->kcpq", {w, psf});
  const torch::Tensor den = w.sum(1).view({1, -1, 1, 1});
  return num / den.clamp_min(1e-30) * (den > 0);  // guarded: a channel with no response gets zeros
}

torch::Tensor wiener_preinverse(const torch::Tensor& image, const torch::Tensor& rgb_psf, double reg) {
  if (image.dim() != 4 || rgb_psf.dim() != 4 || rgb_psf.size(1) != image.size(1) || rgb_psf.size(2) != rgb_psf.size(3) ||
      rgb_psf.size(2) % 2 == 0)
    throw InputError("wiener_preinverse: image must be [B, C, H, W] and psf [K, C, P, P] with P odd, got " +
                     c10::str(image.sizes()) + " and " + c10::str(rgb_psf.sizes()));
  if (!(reg > 0)) throw InputError("wiener_preinverse: the regulariser must be > 0");
  const int64_t B = image.size(0), C = image.size(1), H = image.size(2), W = image.size(3);
  const int64_t K = rgb_psf.size(0), P = rgb_psf.size(2), r = P / 2;
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r);
  const auto dtype = image.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  // Edge-replicated extension: r on the top and left, the rest on the bottom and right.
  const torch::Tensor x = F::pad(image.to(dtype), F::PadFuncOptions({r, nw - W - r, r, nh - H - r}).mode(torch::kReplicate));
  // OTFs with the PSF's centre at (0, 0).
  const torch::Tensor Hf = torch::fft::rfft2(centred_padded_psf(rgb_psf.to(dtype), nh, nw));  // [K, C, nh, nw/2+1]
  const torch::Tensor power = torch::real(Hf).square() + torch::imag(Hf).square();
  const torch::Tensor G = torch::conj(Hf) / (power + reg);                      // the Wiener filters
  const torch::Tensor Y = torch::fft::rfft2(x).unsqueeze(1);                   // [B, 1, C, nh, nw/2+1]
  const torch::Tensor X = torch::fft::irfft2(Y * G.unsqueeze(0), c10::IntArrayRef{nh, nw});  // [B, K, C, nh, nw]
  return X.narrow(3, r, H).narrow(4, r, W).reshape({B, K * C, H, W});
}

torch::Tensor centred_padded_psf(const torch::Tensor& psf, int64_t nh, int64_t nw) {
  const int64_t P = psf.size(-1), r = P / 2;
  return torch::roll(F::pad(psf, F::PadFuncOptions({0, nw - P, 0, nh - P})), {-r, -r}, {-2, -1});
}

torch::Tensor preinverse_layer_mean(const torch::Tensor& preinverse, int64_t layers) {
  TORCH_CHECK(layers > 0 && preinverse.dim() == 4 && preinverse.size(1) % layers == 0,
              "pre-inversion must be [B, K*C, H, W] with K = ", layers, ", got ", preinverse.sizes());
  const int64_t C = preinverse.size(1) / layers;
  return preinverse.reshape({preinverse.size(0), layers, C, preinverse.size(2), preinverse.size(3)}).mean(1);
}

}  // namespace hsd::model
