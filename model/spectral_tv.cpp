#include "model/spectral_tv.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::model {

namespace F = torch::nn::functional;

namespace {

// The per-direction Grams E_z[h_jz h_jzᴴ] of h_jz = Ω diag(K_z) u_j, Kf
// [L, K, F] (K = 1 with the mean OTF gives (H̄ u_j)(H̄ u_j)ᴴ): the six
// entries (00, 11, 22 real; 01, 02, 12 complex) [R, F] each.
struct DirectionGrams {
  torch::Tensor t00, t11, t22, t01, t02, t12;
};

DirectionGrams direction_grams(const torch::Tensor& Kf, const torch::Tensor& Om, const torch::Tensor& Ur) {
  const int64_t L = Kf.size(0), K = Kf.size(1), R = Ur.size(1);
  // rows (c, j): Ω_cλ u_λj, complex for the product with the OTFs
  const torch::Tensor Wq = (Om.unsqueeze(2) * Ur.unsqueeze(0)).transpose(1, 2).reshape({3 * R, L}).to(torch::kComplexDouble);
  const int64_t chunk = std::max<int64_t>(256, (int64_t(1) << 21) / std::max<int64_t>(1, 3 * R * K));
  std::vector<torch::Tensor> a00, a11, a22, a01, a02, a12;
  for (const torch::Tensor& block : Kf.split(chunk, 2)) {
    const int64_t n = block.size(2);
    const torch::Tensor q = torch::matmul(Wq, block.reshape({L, K * n})).view({3, R, K, n});
    const torch::Tensor q0 = q.select(0, 0), q1 = q.select(0, 1), q2 = q.select(0, 2);
    a00.push_back(torch::real(q0 * q0.conj()).mean(1));
    a11.push_back(torch::real(q1 * q1.conj()).mean(1));
    a22.push_back(torch::real(q2 * q2.conj()).mean(1));
    a01.push_back((q0 * q1.conj()).mean(1));
    a02.push_back((q0 * q2.conj()).mean(1));
    a12.push_back((q1 * q2.conj()).mean(1));
  }
  return {torch::cat(a00, 1), torch::cat(a11, 1), torch::cat(a22, 1),
          torch::cat(a01, 1), torch::cat(a02, 1), torch::cat(a12, 1)};
}

}  // namespace

torch::Tensor spectral_tv_cube(const torch::Tensor& image, const SpectralOtf& otf, const torch::Tensor& omega,
                               const SpectralPrior& prior, const EdgePriorSettings& s) {
  if (!(std::isfinite(s.weight) && s.weight >= 0) || (s.weight > 0 && s.iterations < 1) ||
      !(std::isfinite(s.rho_start) && s.rho_start > 0) || !(std::isfinite(s.rho_factor) && s.rho_factor > 1))
    throw InputError("spectral_tv_cube: the edge prior needs weight >= 0, iterations >= 1, rho_start > 0 and "
                     "rho_factor > 1");
  if (!otf.Kf.defined() || otf.Kf.dim() != 3)
    throw InputError("spectral_tv_cube: the OTFs must carry their layers (spectral_otf's Kf [L, K, F])");
  const int64_t L = otf.Kf.size(0);
  if (image.dim() != 4 || image.size(1) != 3 || image.size(2) != otf.H || image.size(3) != otf.W)
    throw InputError("spectral_tv_cube: the OTFs are for [B, 3, " + std::to_string(otf.H) + ", " + std::to_string(otf.W) +
                     "] images, got " + c10::str(image.sizes()));
  if (omega.dim() != 2 || omega.size(0) != 3 || omega.size(1) != L || !prior.mean.defined() ||
      !prior.covariance.defined() || prior.mean.numel() != L || prior.covariance.sizes() != torch::IntArrayRef{L, L} ||
      !(prior.noise_var > 0))
    throw InputError("spectral_tv_cube: the OTFs have " + std::to_string(L) +
                     " bands; omega must be [3, L], the prior's mean [L] and covariance [L, L], its noise variance > 0");
  torch::NoGradGuard no_grad;
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(image.device());
  const int64_t B = image.size(0), H = otf.H, W = otf.W, r = otf.r, nh = otf.nh, nw = otf.nw, nf = nw / 2 + 1;
  const int64_t F_ = nh * nf;
  const auto dtype = image.scalar_type() == torch::kFloat64 ? torch::kFloat64 : torch::kFloat32;
  const double s2 = prior.noise_var;

  const torch::Tensor Om = omega.to(f64).detach(), mu = prior.mean.to(f64).reshape({L});
  // Σ = U diag(e) Uᵀ over the directions that carry variance
  const SpectralDirections dirs = spectral_directions(prior.covariance);
  const torch::Tensor &e = dirs.e, &Ur = dirs.U;  // [R], [L, R]
  const torch::Tensor Uc = Ur.to(torch::kComplexDouble), Utc = Uc.t().contiguous();
  const torch::Tensor Oc = Om.to(torch::kComplexDouble), Otc = Oc.t().contiguous();

  const torch::Tensor S = spectral_wiener_psd(nh, nw, prior.psd_exponent, image.device());  // [F]
  const torch::Tensor fy = torch::fft::fftfreq(nh, f64).view({-1, 1}), fx = torch::fft::rfftfreq(nw, f64).view({1, -1});
  // forward differences: D(f) = exp(2πi f) − 1 per axis (torch's DFT sign), |D|² = 4 sin²(π f)
  const double two_pi = 2.0 * M_PI;
  const torch::Tensor Dy = torch::complex(torch::cos(two_pi * fy) - 1.0, torch::sin(two_pi * fy)).expand({nh, nf}).reshape({F_});
  const torch::Tensor Dx = torch::complex(torch::cos(two_pi * fx) - 1.0, torch::sin(two_pi * fx)).expand({nh, nf}).reshape({F_});
  const torch::Tensor D2 = torch::real(Dy * Dy.conj()) + torch::real(Dx * Dx.conj());  // [F]
  const torch::Tensor Se = e.view({-1, 1}) * S.view({1, -1});                           // [R, F]

  // The mixture over the layers as the linear model Y = H̄ X + E, E uncorrelated
  // with X, of covariance N = S (E_z[H_z Σ H_zᴴ] − H̄ Σ H̄ᴴ) + σ² I (the same
  // first and second moments, hence the same LMMSE cube at ρ = 0); the x-step
  // is then the exact minimiser of the quadratic energy, and
  //   M(ρ) = Σ_j c_j T̄_j + N,  T̄_j = (H̄ u_j)(H̄ u_j)ᴴ.
  const torch::Tensor& Kbar = otf.Kbar;  // [L, F]
  const DirectionGrams T = direction_grams(otf.Kf, Om, Ur), Tb = direction_grams(Kbar.unsqueeze(1), Om, Ur);
  auto spread = [&](const torch::Tensor& t, const torch::Tensor& tb) { return (Se * (t - tb)).sum(0); };
  const torch::Tensor n00 = spread(T.t00, Tb.t00) + s2, n11 = spread(T.t11, Tb.t11) + s2, n22 = spread(T.t22, Tb.t22) + s2;
  const torch::Tensor n01 = spread(T.t01, Tb.t01), n02 = spread(T.t02, Tb.t02), n12 = spread(T.t12, Tb.t12);

  torch::Tensor y = image.to(f64) - torch::matmul(Om, mu).view({1, 3, 1, 1});
  y = F::pad(y, F::PadFuncOptions({r, nw - W - r, r, nh - H - r}).mode(torch::kReplicate));
  const torch::Tensor Y = torch::fft::rfft2(y).reshape({B, 3, F_});

  // The x-step for ρ (absolute, 1/radiance²) and Dᴴ V [B, L, F] (undefined: ρ = 0, the Wiener cube).
  auto x_step = [&](double rho, const torch::Tensor& DhV) {
    const torch::Tensor c = rho > 0 ? Se / (1.0 + rho * D2.view({1, -1}) * Se) : Se;  // [R, F]
    const Hermitian3Inverse Minv = hermitian3_inverse(
        {(c * Tb.t00).sum(0) + n00, (c * Tb.t11).sum(0) + n11, (c * Tb.t22).sum(0) + n22,
         (c * Tb.t01).sum(0) + n01, (c * Tb.t02).sum(0) + n02, (c * Tb.t12).sum(0) + n12});
    const torch::Tensor cc = c.to(torch::kComplexDouble);
    torch::Tensor mean, resid = Y;
    if (DhV.defined()) {
      mean = rho * torch::matmul(Uc, cc * torch::matmul(Utc, DhV));  // ρ C' Dᴴ V [B, L, F]
      resid = Y - torch::matmul(Oc, Kbar * mean);
    }
    const auto z = Minv.solve(resid.select(1, 0), resid.select(1, 1), resid.select(1, 2));
    const torch::Tensor Z = torch::stack({z[0], z[1], z[2]}, 1);  // M⁻¹ (Y − H̄ m) [B, 3, F]
    const torch::Tensor g = Kbar.conj() * torch::matmul(Otc, Z);           // H̄ᴴ · [B, L, F]
    torch::Tensor X = torch::matmul(Uc, cc * torch::matmul(Utc, g));       // C' H̄ᴴ M⁻¹ (…)
    return mean.defined() ? X + mean : X;
  };
  auto spatial = [&](const torch::Tensor& X) {
    return torch::fft::irfft2(X.view({B, L, nh, nf}), c10::IntArrayRef{nh, nw});  // [B, L, nh, nw], periodic
  };

  torch::Tensor X = x_step(0.0, {});
  if (s.weight > 0) {
    double rho_rel = s.rho_start;
    for (int64_t k = 0; k < s.iterations; ++k, rho_rel *= s.rho_factor) {
      const torch::Tensor x = spatial(X);
      const torch::Tensor gx = x.roll(-1, 3) - x, gy = x.roll(-1, 2) - x;
      const torch::Tensor norm = (gx.square() + gy.square()).sum(1, /*keepdim=*/true).sqrt();  // [B, 1, nh, nw]
      const torch::Tensor shrink = (1.0 - (s.weight / rho_rel) / norm.clamp_min(1e-300)).clamp_min(0.0);
      const torch::Tensor Vx = torch::fft::rfft2(gx * shrink).reshape({B, L, F_});
      const torch::Tensor Vy = torch::fft::rfft2(gy * shrink).reshape({B, L, F_});
      X = x_step(rho_rel / s2, Dx.conj() * Vx + Dy.conj() * Vy);
    }
  }
  const torch::Tensor x = spatial(X).narrow(2, r, H).narrow(3, r, W) + mu.view({1, L, 1, 1});
  if (!torch::isfinite(x).all().item<bool>())
    throw NumericalError("spectral_tv_cube: the cube is not finite (check the PSFs and the prior)");
  return x.to(dtype).contiguous();
}

torch::Tensor coupled_total_variation(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4 && x.size(2) >= 2 && x.size(3) >= 2, "coupled_total_variation: x must be [B, L, H >= 2, W >= 2]");
  const int64_t H = x.size(2), W = x.size(3);
  const torch::Tensor c = x.narrow(2, 0, H - 1).narrow(3, 0, W - 1);
  const torch::Tensor gx = x.narrow(2, 0, H - 1).narrow(3, 1, W - 1) - c;
  const torch::Tensor gy = x.narrow(2, 1, H - 1).narrow(3, 0, W - 1) - c;
  return (gx.square() + gy.square()).sum(1).sqrt().sum({1, 2});
}

}  // namespace hsd::model
