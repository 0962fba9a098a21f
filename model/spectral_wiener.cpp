#include "model/spectral_wiener.h"

#include <algorithm>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "common/error.h"
#include "common/fft_size.h"

namespace hsd::model {

namespace F = torch::nn::functional;

SpectralDirections spectral_directions(const torch::Tensor& covariance) {
  torch::NoGradGuard no_grad;
  const torch::Tensor Sig = covariance.to(torch::kFloat64);
  const auto eig = torch::linalg_eigh(0.5 * (Sig + Sig.t()));
  const torch::Tensor e = std::get<0>(eig);
  // eigenvalues at rounding level (and negative ones, from rounding) carry nothing
  const torch::Tensor keep = e > 1e-14 * e.abs().max().clamp_min(1e-300);
  return {e.index({keep}), std::get<1>(eig).index({torch::indexing::Slice(), keep})};
}

Hermitian3Inverse hermitian3_inverse(const Hermitian3& m) {
  Hermitian3Inverse v;
  v.c00 = m.m11 * m.m22 - torch::real(m.m12 * m.m12.conj());
  v.c11 = m.m00 * m.m22 - torch::real(m.m02 * m.m02.conj());
  v.c22 = m.m00 * m.m11 - torch::real(m.m01 * m.m01.conj());
  v.c01 = m.m02 * m.m12.conj() - m.m01 * m.m22;  // adj(M)_01
  v.c02 = m.m01 * m.m12 - m.m02 * m.m11;          // adj(M)_02
  v.c12 = m.m02 * m.m01.conj() - m.m00 * m.m12;  // adj(M)_12
  v.inv_det = 1.0 / (m.m00 * v.c00 + torch::real(m.m01 * v.c01.conj()) + torch::real(m.m02 * v.c02.conj()));
  return v;
}

std::array<torch::Tensor, 3> Hermitian3Inverse::solve(const torch::Tensor& r0, const torch::Tensor& r1,
                                                      const torch::Tensor& r2) const {
  return {(c00 * r0 + c01 * r1 + c02 * r2) * inv_det, (c01.conj() * r0 + c11 * r1 + c12 * r2) * inv_det,
          (c02.conj() * r0 + c12.conj() * r1 + c22 * r2) * inv_det};
}

torch::Tensor spectral_wiener_factor(const torch::Tensor& omega, const torch::Tensor& covariance) {
  torch::NoGradGuard no_grad;
  const torch::Tensor Om = omega.to(torch::kFloat64);
  const int64_t L = Om.size(1);
  const SpectralDirections d = spectral_directions(covariance);
  const torch::Tensor V = d.U * d.e.sqrt().view({1, -1});                                   // [L, R]
  return (Om.unsqueeze(2) * V.unsqueeze(0)).transpose(1, 2).reshape({-1, L}).contiguous();  // [3R, L]
}

void check_spectral_inputs(const char* who, const torch::Tensor& image, const torch::Tensor& psf,
                           const torch::Tensor& omega, const SpectralPrior& prior) {
  if (image.dim() != 4 || image.size(1) != 3 || psf.dim() != 4 || psf.size(2) != psf.size(3) || psf.size(2) % 2 == 0 ||
      omega.dim() != 2 || omega.size(0) != 3 || omega.size(1) != psf.size(0))
    throw InputError(std::string(who) + ": image must be [B, 3, H, W], psf [L, K, P, P] with P odd and omega [3, L], got " +
                     c10::str(image.sizes()) + ", " + c10::str(psf.sizes()) + " and " + c10::str(omega.sizes()));
  const int64_t L = psf.size(0);
  if (!prior.mean.defined() || !prior.covariance.defined() || prior.mean.numel() != L ||
      prior.covariance.sizes() != torch::IntArrayRef{L, L})
    throw InputError(std::string(who) + ": the prior needs a mean [" + std::to_string(L) + "] and a covariance [" +
                     std::to_string(L) + ", " + std::to_string(L) + "]");
  if (!(prior.noise_var > 0)) throw InputError(std::string(who) + ": the noise variance must be > 0");
}

SpectralOtf spectral_otf(const torch::Tensor& psf, int64_t H, int64_t W) {
  if (psf.dim() != 4 || psf.size(2) != psf.size(3) || psf.size(2) % 2 == 0 || H < 1 || W < 1)
    throw InputError("spectral_otf: psf must be [L, K, P, P] with P odd and the image at least 1 x 1, got " +
                     c10::str(psf.sizes()) + " and " + std::to_string(H) + " x " + std::to_string(W));
  SpectralOtf o;
  const int64_t L = psf.size(0), K = psf.size(1), P = psf.size(2), r = P / 2;
  o.H = H, o.W = W, o.r = r, o.nh = fast_fft_size(H + 2 * r), o.nw = fast_fft_size(W + 2 * r);
  const int64_t F_ = o.nh * (o.nw / 2 + 1);
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(psf.device());
  // OTFs K_λz(f) [L, K, F], float64: the PSF placed with its centre at pixel
  // (0, 0) by its four quadrants (no padded copy rolled afterwards).
  torch::Tensor k = torch::zeros({L, K, o.nh, o.nw}, f64);
  {
    const torch::Tensor p = psf.to(f64);
    const int64_t a = P - r, nh = o.nh, nw = o.nw;  // rows/columns r..P-1 of the PSF go to 0..a-1
    k.narrow(2, 0, a).narrow(3, 0, a).copy_(p.narrow(2, r, a).narrow(3, r, a));
    k.narrow(2, 0, a).narrow(3, nw - r, r).copy_(p.narrow(2, r, a).narrow(3, 0, r));
    k.narrow(2, nh - r, r).narrow(3, 0, a).copy_(p.narrow(2, 0, r).narrow(3, r, a));
    k.narrow(2, nh - r, r).narrow(3, nw - r, r).copy_(p.narrow(2, 0, r).narrow(3, 0, r));
  }
  o.Kf = torch::fft::rfft2(k).reshape({L, K, F_});  // [L, K, F]
  o.Kbar = o.Kf.mean(1);                           // [L, F]
  return o;
}

SpectralWienerFilter spectral_wiener_filter(const SpectralOtf& otf, const torch::Tensor& omega, const SpectralPrior& prior) {
  const int64_t L = otf.Kf.size(0), K = otf.Kf.size(1);
  if (omega.dim() != 2 || omega.size(0) != 3 || omega.size(1) != L || !prior.mean.defined() ||
      !prior.covariance.defined() || prior.mean.numel() != L || prior.covariance.sizes() != torch::IntArrayRef{L, L} ||
      !(prior.noise_var > 0))
    throw InputError("spectral_wiener_filter: the OTFs have " + std::to_string(L) +
                     " bands; omega must be [3, L], the prior's mean [L] and covariance [L, L], its noise variance > 0");
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(otf.Kf.device());
  SpectralWienerFilter w;
  w.otf = otf;
  // No gradient flows into Ω or Σ (the camera response and the prior are fixed).
  w.Om = omega.to(f64).detach(), w.mu = prior.mean.to(f64).reshape({L});
  w.Sig = prior.covariance.to(f64).detach();

  // E_z[H_z Σ H_zᴴ] with H_z = Ω diag(K_z) and Σ = V Vᵀ (spectral_wiener_factor,
  // rank R): the Gram matrix (1/K) Σ_z Q_z Q_zᴴ of Q_z = Ω diag(K_z) V [3, R].
  // Q is one real GEMM per block of frequencies, [3R, L] · [L, 2·K·n] (the
  // OTFs' real view), and the Gram its three squared norms and three products
  // summed along R·K; a block holds about 4 MiB of Q. (Formed as F batched
  // products of L × K by K × L complex matrices instead, the whole filter took
  // 2.1-3.1× as long at the paper's 25 bands and 7 layers: docs/benchmarks.md.)
  const torch::Tensor Vq = spectral_wiener_factor(w.Om, w.Sig);  // [3R, L], rows (c, j)
  const int64_t rk = Vq.size(0) / 3 * K;                         // R·K
  const int64_t chunk = std::max<int64_t>(256, (int64_t(1) << 22) / std::max<int64_t>(1, 3 * rk * 16));
  std::vector<torch::Tensor> a00, a11, a22, a01, a02, a12;
  // split, not narrow per block: the blocks' gradients then meet in one concatenation
  for (const torch::Tensor& block : otf.Kf.split(chunk, 2)) {
    const int64_t n = block.size(2);
    const torch::Tensor kc = torch::view_as_real(block.contiguous()).reshape({L, K * n * 2});
    const torch::Tensor qr = torch::matmul(Vq, kc).view({3, rk, n * 2});  // Q's real view [3, R·K, n·2]
    const torch::Tensor q = torch::view_as_complex(qr.view({3, rk, n, 2}));
    // sums along R·K as reductions over the leading dimension of 2-D real views
    auto diag = [&](int64_t c) { return qr.select(0, c).square().sum(0).view({n, 2}).sum(1); };
    auto off = [&](int64_t c, int64_t d) {
      return torch::view_as_complex(torch::view_as_real(q.select(0, c) * q.select(0, d).conj()).view({rk, n * 2}).sum(0).view({n, 2}));
    };
    a00.push_back(diag(0));
    a11.push_back(diag(1));
    a22.push_back(diag(2));
    a01.push_back(off(0, 1));
    a02.push_back(off(0, 2));
    a12.push_back(off(1, 2));
  }
  const double inv_k = 1.0 / double(K);
  const torch::Tensor A00 = torch::cat(a00) * inv_k, A11 = torch::cat(a11) * inv_k, A22 = torch::cat(a22) * inv_k;
  const torch::Tensor A01 = torch::cat(a01) * inv_k, A02 = torch::cat(a02) * inv_k, A12 = torch::cat(a12) * inv_k;

  w.S = spectral_wiener_psd(otf.nh, otf.nw, prior.psd_exponent, otf.Kf.device());
  const torch::Tensor& S = w.S;

  // M = S A + σ² I (Hermitian), inverted by cofactors per frequency.
  const double s2 = prior.noise_var;
  w.Minv = hermitian3_inverse({S * A00 + s2, S * A11 + s2, S * A22 + s2, S * A01, S * A02, S * A12});
  w.otf.Kf = torch::Tensor();  // applying needs K̄ only
  return w;
}

namespace {

// X̂ = S Σ diag(conj K̄) Ωᵀ M⁻¹ Y per frequency, for an image spectrum Y
// [B, 3, F] (complex128) -> [B, L, F] (complex128): M⁻¹ per frequency, then
// real GEMMs with Ωᵀ and Σ over the spectrum's real view, float64 throughout.
torch::Tensor filter_spectrum(const SpectralWienerFilter& w, const torch::Tensor& Y) {
  const int64_t L = w.Om.size(1), B = Y.size(0), F_ = Y.size(2);
  const auto Z = w.Minv.solve(Y.select(1, 0), Y.select(1, 1), Y.select(1, 2));
  const torch::Tensor Zr = torch::view_as_real(torch::stack({Z[0], Z[1], Z[2]}, 0)).reshape({3, B * F_ * 2});  // [3, B·F·2]
  torch::Tensor u = torch::view_as_complex(torch::matmul(w.Om.t(), Zr).view({L, B, F_, 2}));            // Ωᵀ Z [L, B, F]
  u = u * w.otf.Kbar.conj().unsqueeze(1);
  const torch::Tensor xr = torch::matmul(w.Sig, torch::view_as_real(u).reshape({L, B * F_ * 2})).view({L, B, F_, 2});
  return (torch::view_as_complex(xr) * w.S).transpose(0, 1);
}

}  // namespace

torch::Tensor apply_spectral_wiener(const SpectralWienerFilter& w, const torch::Tensor& image) {
  const SpectralOtf& o = w.otf;
  const int64_t L = w.Om.size(1), B = image.size(0), H = image.size(2), W = image.size(3), r = o.r;
  if (image.dim() != 4 || image.size(1) != 3 || H != o.H || W != o.W)
    throw InputError("apply_spectral_wiener: the filter is for [B, 3, " + std::to_string(o.H) + ", " + std::to_string(o.W) +
                     "] images, got " + c10::str(image.sizes()));
  const int64_t nh = o.nh, nw = o.nw, nf = nw / 2 + 1, F_ = nh * nf;
  const auto dtype = image.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  // X̂ = S Σ diag(conj K̄) Ωᵀ M⁻¹ (Y − Ω μ δ_f0), the cube returned to the
  // image's precision before the inverse FFT.
  torch::Tensor y = image.to(torch::kFloat64) - torch::matmul(w.Om, w.mu).view({1, 3, 1, 1});
  y = F::pad(y, F::PadFuncOptions({r, nw - W - r, r, nh - H - r}).mode(torch::kReplicate));
  const torch::Tensor Y = torch::fft::rfft2(y).reshape({B, 3, F_});
  const auto cdt = dtype == torch::kFloat64 ? torch::kComplexDouble : torch::kComplexFloat;
  const torch::Tensor X = filter_spectrum(w, Y).to(cdt).reshape({B, L, nh, nf});
  const torch::Tensor x = torch::fft::irfft2(X, c10::IntArrayRef{nh, nw});
  return x.narrow(2, r, H).narrow(3, r, W) + w.mu.to(dtype).view({1, L, 1, 1});
}

torch::Tensor spectral_wiener_unobserved(const SpectralWienerFilter& w, const torch::Tensor& delta) {
  const SpectralOtf& o = w.otf;
  const int64_t L = w.Om.size(1);
  if (delta.dim() != 4 || delta.size(1) != L || delta.size(2) != o.H || delta.size(3) != o.W)
    throw InputError("spectral_wiener_unobserved: the filter is for [B, " + std::to_string(L) + ", " +
                     std::to_string(o.H) + ", " + std::to_string(o.W) + "] cubes, got " + c10::str(delta.sizes()));
  const int64_t B = delta.size(0), H = o.H, W = o.W, r = o.r, nh = o.nh, nw = o.nw, nf = nw / 2 + 1, F_ = nh * nf;
  // δ is zero beyond the cube (a correction where it is given, none outside),
  // so it is zero-padded, not edge-replicated as an image is.
  const torch::Tensor d = F::pad(delta.to(torch::kFloat64), F::PadFuncOptions({r, nw - W - r, r, nh - H - r}));
  const torch::Tensor D = torch::fft::rfft2(d).reshape({B, L, F_});  // [B, L, F]
  // H̄ δ: each band through its mean OTF, then the camera response Ω (a real
  // GEMM over the spectrum's real view).
  const torch::Tensor Kd = torch::view_as_real(D * o.Kbar.unsqueeze(0)).reshape({B, L, F_ * 2});
  const torch::Tensor Y = torch::view_as_complex(torch::matmul(w.Om, Kd).view({B, 3, F_, 2}).contiguous());
  const torch::Tensor X = (D - filter_spectrum(w, Y)).reshape({B, L, nh, nf});
  const auto dtype = delta.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  return torch::fft::irfft2(X, c10::IntArrayRef{nh, nw}).narrow(2, r, H).narrow(3, r, W).to(dtype);
}

torch::Tensor spectral_wiener_cube(const torch::Tensor& image, const torch::Tensor& psf, const torch::Tensor& omega,
                                   const SpectralPrior& prior) {
  check_spectral_inputs("spectral_wiener_cube", image, psf, omega, prior);
  const SpectralOtf otf = spectral_otf(psf, image.size(2), image.size(3));
  return apply_spectral_wiener(spectral_wiener_filter(otf, omega, prior), image);
}

torch::Tensor spectral_wiener_psd(int64_t nh, int64_t nw, double exponent, const torch::Device& device) {
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(device);
  const torch::Tensor fy = torch::fft::fftfreq(nh, f64).view({-1, 1}), fx = torch::fft::rfftfreq(nw, f64).view({1, -1});
  torch::Tensor S = torch::pow(torch::sqrt(fy.square() + fx.square()) + 1.0 / double(std::max(nh, nw)), -exponent);
  S = S.flatten();
  S = S / S.slice(0, 1).mean();
  return torch::cat({S.slice(0, 0, 1) * 1e4, S.slice(0, 1)});
}

double mean_noise_variance(double std_min, double std_max, double photons_at_saturation, double y_mean) {
  const double lo = std_min < 0 ? std_max : std_min, hi = std_max;
  const double read = (lo * lo + lo * hi + hi * hi) / 3.0;  // E[σ²] for σ ~ U[lo, hi]
  const double shot = photons_at_saturation > 0 ? std::max(0.0, y_mean) / photons_at_saturation : 0.0;
  return std::max(1e-8, read + shot);
}

}  // namespace hsd::model
