#include "model/spectral_wiener.h"

#include <algorithm>

#include <torch/torch.h>

#include "common/error.h"
#include "common/fft_size.h"

namespace hsd::model {

namespace F = torch::nn::functional;

namespace {

// m [..., 3, 3] (invertible) -> m⁻¹ = adj(m) / det(m), elementwise over the leading dimensions.
torch::Tensor inverse3x3(const torch::Tensor& m) {
  auto e = [&](int64_t r, int64_t c) { return m.select(-2, r).select(-1, c); };
  const torch::Tensor a = e(0, 0), b = e(0, 1), c = e(0, 2), d = e(1, 0), ee = e(1, 1), f = e(1, 2), g = e(2, 0),
                      h = e(2, 1), i = e(2, 2);
  const torch::Tensor c00 = ee * i - f * h, c01 = f * g - d * i, c02 = d * h - ee * g;
  const torch::Tensor det = a * c00 + b * c01 + c * c02;
  const torch::Tensor adj = torch::stack({torch::stack({c00, c * h - b * i, b * f - c * ee}, -1),
                                          torch::stack({c01, a * i - c * g, c * d - a * f}, -1),
                                          torch::stack({c02, b * g - a * h, a * ee - b * d}, -1)},
                                         -2);
  return adj / det.unsqueeze(-1).unsqueeze(-1);
}

}  // namespace

torch::Tensor spectral_wiener_cube(const torch::Tensor& image, const torch::Tensor& psf, const torch::Tensor& omega,
                                   const SpectralPrior& prior) {
  if (image.dim() != 4 || image.size(1) != 3 || psf.dim() != 4 || psf.size(2) != psf.size(3) || psf.size(2) % 2 == 0 ||
      omega.dim() != 2 || omega.size(0) != 3 || omega.size(1) != psf.size(0))
    throw InputError("spectral_wiener_cube: image must be [B, 3, H, W], psf [L, K, P, P] with P odd and omega [3, L], got " +
                     c10::str(image.sizes()) + ", " + c10::str(psf.sizes()) + " and " + c10::str(omega.sizes()));
  const int64_t L = psf.size(0), K = psf.size(1), P = psf.size(2), r = P / 2;
  if (!prior.mean.defined() || !prior.covariance.defined() || prior.mean.numel() != L ||
      prior.covariance.sizes() != torch::IntArrayRef{L, L})
    throw InputError("spectral_wiener_cube: the prior needs a mean [" + std::to_string(L) + "] and a covariance [" +
                     std::to_string(L) + ", " + std::to_string(L) + "]");
  if (!(prior.noise_var > 0)) throw InputError("spectral_wiener_cube: the noise variance must be > 0");
  const int64_t B = image.size(0), H = image.size(2), W = image.size(3);
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r), nf = nw / 2 + 1;
  const auto dtype = image.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(image.device());
  const auto c128 = torch::TensorOptions().dtype(torch::kComplexDouble).device(image.device());
  const torch::Tensor Om = omega.to(f64), mu = prior.mean.to(f64).reshape({L});
  const torch::Tensor Sig = prior.covariance.to(f64).to(torch::kComplexDouble);
  // The filter [F, L, 3], in float64.
  torch::Tensor k = F::pad(psf.to(f64), F::PadFuncOptions({0, nw - P, 0, nh - P}));
  k = torch::roll(k, {-r, -r}, {2, 3});
  // With H_z = Ω diag(K_z): E_z[H_z Σ H_zᴴ] = Ω (Σ ∘ G) Ωᵀ, G_λμ = E_z[K_λz conj(K_μz)],
  // and Σ H̄ᴴ = (Σ ∘ conj(K̄)ᵀ-rows) Ωᵀ: large matrix products, not F tiny ones.
  const int64_t F_ = nh * nf;
  const torch::Tensor Kf = torch::fft::rfft2(k).reshape({L, K, F_}).permute({2, 0, 1});  // OTFs [F, L, K]
  const torch::Tensor G = torch::matmul(Kf, Kf.conj().transpose(1, 2)) / double(K);     // [F, L, L]
  const torch::Tensor Oc = Om.to(torch::kComplexDouble);                                 // [3, L]
  const torch::Tensor T = torch::matmul((G * Sig.unsqueeze(0)).reshape({F_ * L, L}), Oc.t()).reshape({F_, L, 3});
  const torch::Tensor A = torch::matmul(T.transpose(0, 1).reshape({L, F_ * 3}).t(), Oc.t()).reshape({F_, 3, 3}).transpose(1, 2);  // Ω T [F, 3, 3]
  const torch::Tensor Kbar = Kf.mean(2);                                                 // [F, L]
  const torch::Tensor C =
      torch::matmul((Sig.unsqueeze(0) * Kbar.conj().unsqueeze(1)).reshape({F_ * L, L}), Oc.t()).reshape({F_, L, 3});  // Σ H̄ᴴ
  const torch::Tensor fy = torch::fft::fftfreq(nh, f64).view({-1, 1}), fx = torch::fft::rfftfreq(nw, f64).view({1, -1});
  torch::Tensor S = torch::pow(torch::sqrt(fy.square() + fx.square()) + 1.0 / double(std::max(nh, nw)), -prior.psd_exponent);
  S = S.flatten();
  S = S / S.slice(0, 1).mean();
  S = torch::cat({S.slice(0, 0, 1) * 1e4, S.slice(0, 1)});
  // W = S C (S A + σ² I)⁻¹, the 3×3 inverse by cofactors (elementwise over
  // the frequencies: a batched LAPACK solve of 3×3 systems is ~10× slower).
  const torch::Tensor M = S.view({-1, 1, 1}) * A + prior.noise_var * torch::eye(3, c128);
  const torch::Tensor Wf = torch::matmul(S.view({-1, 1, 1}) * C, inverse3x3(M));
  // Apply to the image minus the prior's mean image, edge-replicated.
  const auto cdt = dtype == torch::kFloat64 ? torch::kComplexDouble : torch::kComplexFloat;
  torch::Tensor y = image.to(dtype) - torch::matmul(Om, mu).to(dtype).view({1, 3, 1, 1});
  y = F::pad(y, F::PadFuncOptions({r, nw - W - r, r, nh - H - r}).mode(torch::kReplicate));
  const torch::Tensor Y = torch::fft::rfft2(y).reshape({B, 3, nh * nf});            // [B, 3, F]
  const torch::Tensor X = torch::einsum("flc,bcf->blf", {Wf.to(cdt), Y}).reshape({B, L, nh, nf});
  const torch::Tensor x = torch::fft::irfft2(X, c10::IntArrayRef{nh, nw});
  return x.narrow(2, r, H).narrow(3, r, W) + mu.to(dtype).view({1, L, 1, 1});
}

double mean_noise_variance(double std_min, double std_max, double photons_at_saturation, double y_mean) {
  const double lo = std_min < 0 ? std_max : std_min, hi = std_max;
  const double read = (lo * lo + lo * hi + hi * hi) / 3.0;  // E[σ²] for σ ~ U[lo, hi]
  const double shot = photons_at_saturation > 0 ? std::max(0.0, y_mean) / photons_at_saturation : 0.0;
  return std::max(1e-8, read + shot);
}

}  // namespace hsd::model
