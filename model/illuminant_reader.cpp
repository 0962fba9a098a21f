#include "model/illuminant_reader.h"

#include <algorithm>
#include <cmath>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::model {

namespace {
constexpr int64_t kIntensitySteps = 49;  // the log grid of the profiled intensity

void check_moments(const char* who, const IlluminantMoments& m) {
  if (!m.mean.defined() || !m.second.defined() || m.mean.dim() != 2 || m.second.dim() != 3 ||
      m.second.size(0) != m.mean.size(0) || m.second.size(1) != m.mean.size(1) || m.second.size(2) != m.mean.size(1) ||
      m.mean.size(0) < 1)
    throw InputError(std::string(who) + ": the illuminant moments must be a mean [K, L] and a second moment [K, L, L]");
  if (!(m.intensity_min > 0 && m.intensity_max >= m.intensity_min))
    throw InputError(std::string(who) + ": the intensity range must satisfy 0 < min <= max");
}
}  // namespace

torch::Tensor illuminant_intensity_grid(double intensity_min, double intensity_max) {
  if (!(intensity_min > 0 && intensity_max >= intensity_min))
    throw InputError("illuminant_intensity_grid: the intensity range must satisfy 0 < min <= max");
  return torch::logspace(std::log10(0.5 * intensity_min), std::log10(2.0 * intensity_max), kIntensitySteps, 10.0,
                         torch::TensorOptions().dtype(torch::kFloat64));
}

IlluminantMoments illuminant_moments(const torch::Tensor& reflectance_mean, const torch::Tensor& reflectance_second,
                                     const torch::Tensor& illuminants, double intensity_min, double intensity_max) {
  const int64_t L = reflectance_mean.numel();
  if (reflectance_second.sizes() != torch::IntArrayRef{L, L} || illuminants.dim() != 2 || illuminants.size(1) != L ||
      illuminants.size(0) < 1)
    throw InputError("illuminant_moments: need m_r [L], R_r [L, L] and illuminants [K, L] with L = " + std::to_string(L));
  torch::NoGradGuard no_grad;
  const torch::Tensor e = illuminants.to(torch::kFloat64);
  IlluminantMoments m;
  m.mean = e * reflectance_mean.to(torch::kFloat64).reshape({1, L});                                 // [K, L]
  m.second = e.unsqueeze(2) * e.unsqueeze(1) * reflectance_second.to(torch::kFloat64).unsqueeze(0);  // [K, L, L]
  m.intensity_min = intensity_min;
  m.intensity_max = intensity_max;
  check_moments("illuminant_moments", m);
  return m;
}

torch::Tensor illuminant_log_likelihood(const torch::Tensor& image, const torch::Tensor& omega,
                                        const torch::Tensor& band_energy, const IlluminantMoments& m, double noise_var,
                                        int64_t block_px) {
  check_moments("illuminant_log_likelihood", m);
  const int64_t K = m.mean.size(0), L = m.mean.size(1);
  if (image.dim() != 4 || image.size(1) != 3 || omega.sizes() != torch::IntArrayRef{3, L} || band_energy.numel() != L)
    throw InputError("illuminant_log_likelihood: image must be [B, 3, H, W], omega [3, " + std::to_string(L) +
                     "] and the band energy [" + std::to_string(L) + "], got " + c10::str(image.sizes()) + ", " +
                     c10::str(omega.sizes()) + ", " + c10::str(band_energy.sizes()));
  if (!(noise_var > 0) || block_px < 1) throw InputError("illuminant_log_likelihood: need noise_var > 0 and block_px >= 1");
  torch::NoGradGuard no_grad;
  check_finite(image, "illuminant_log_likelihood: the image");
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(image.device());
  const int64_t B = image.size(0), H = image.size(2), W = image.size(3);
  const int64_t bs = std::max<int64_t>(1, std::min({block_px, H, W}));
  // Block means [B, J, 3]; the rows and columns beyond the last whole block are left out.
  const torch::Tensor b =
      torch::nn::functional::avg_pool2d(image.detach().to(f64), torch::nn::functional::AvgPool2dFuncOptions(bs))
          .flatten(2)
          .transpose(1, 2);
  const double J = double(b.size(1));
  const torch::Tensor bm = b.mean(1);                                      // [B, 3]
  const torch::Tensor Q = torch::matmul(b.transpose(1, 2), b) / J;         // [B, 3, 3] Σ_j b bᵀ / J
  const torch::Tensor G = omega.to(f64) * band_energy.to(f64).reshape({1, L});  // [3, L]
  const torch::Tensor mu = m.mean.to(f64), R = m.second.to(f64);
  const torch::Tensor C = R - mu.unsqueeze(2) * mu.unsqueeze(1);                // [K, L, L]
  const torch::Tensor g = torch::matmul(mu, G.t());                              // [K, 3]
  const torch::Tensor A = torch::matmul(torch::matmul(G, C), G.t());            // [K, 3, 3]
  const torch::Tensor s = illuminant_intensity_grid(m.intensity_min, m.intensity_max).to(image.device());  // [S]
  const torch::Tensor eye = torch::eye(3, f64);
  torch::Tensor out = torch::empty({B, K}, f64);
  for (int64_t i = 0; i < B; ++i) {
    const double tau2 = noise_var / double(bs * bs) + kIlluminantModelFloor * (Q[i].diagonal().mean().item<double>() + 1e-300);
    const torch::Tensor s2 = (s * s).view({1, -1, 1, 1});
    const torch::Tensor Sig = s2 * A.unsqueeze(1) + tau2 * eye;                  // [K, S, 3, 3]
    const torch::Tensor Si = torch::linalg_inv(Sig);
    const torch::Tensor logdet = std::get<1>(torch::linalg_slogdet(Sig));        // [K, S]
    // E_j (b − s g)(b − s g)ᵀ = Q − s (m gᵀ + g mᵀ) + s² g gᵀ
    const torch::Tensor mi = bm[i];                                               // [3] the block means' mean
    const torch::Tensor cross = mi.view({1, 3, 1}) * g.unsqueeze(1) + g.unsqueeze(2) * mi.view({1, 1, 3});  // [K, 3, 3]
    const torch::Tensor gg = g.unsqueeze(2) * g.unsqueeze(1);                                              // [K, 3, 3]
    const torch::Tensor D = Q[i].view({1, 1, 3, 3}) - s.view({1, -1, 1, 1}) * cross.unsqueeze(1) +
                            s2 * gg.unsqueeze(1);                                                          // [K, S, 3, 3]
    const torch::Tensor quad = (Si * D).sum({2, 3});  // tr(S⁻¹ D), both symmetric
    const torch::Tensor ll = -0.5 * J * (logdet + quad);                        // [K, S]
    out[i] = std::get<0>(ll.max(1));
  }
  if (!torch::isfinite(out).all().item<bool>())
    throw NumericalError("illuminant_log_likelihood: a non-finite log-likelihood (an image of NaN/Inf?)");
  return out;
}

torch::Tensor illuminant_posterior(const torch::Tensor& log_likelihood, int64_t H, int64_t W,
                                   const IlluminantReaderSettings& st) {
  if (log_likelihood.dim() != 2) throw InputError("illuminant_posterior: the log-likelihood must be [B, K]");
  if (!(st.effective_blocks > 0) || st.block_px < 1)
    throw InputError("illuminant_posterior: need effective_blocks > 0 and block_px >= 1");
  const int64_t bs = std::max<int64_t>(1, std::min({st.block_px, H, W}));
  const double J = double((H / bs) * (W / bs));
  return torch::softmax(log_likelihood.to(torch::kFloat64) * (st.effective_blocks / std::max(J, 1.0)), 1);
}

SpectralPrior illuminant_mixture_prior(const IlluminantMoments& m, const torch::Tensor& weights, double noise_var) {
  check_moments("illuminant_mixture_prior", m);
  const int64_t K = m.mean.size(0);
  if (weights.numel() != K) throw InputError("illuminant_mixture_prior: the weights must be [" + std::to_string(K) + "]");
  torch::NoGradGuard no_grad;
  const double lo = m.intensity_min, hi = m.intensity_max;
  const double es = 0.5 * (lo + hi), es2 = (lo * lo + lo * hi + hi * hi) / 3.0;  // E[s], E[s²] for s ~ U[lo, hi]
  const torch::Tensor w = weights.to(torch::kFloat64).reshape({K});
  const torch::Tensor mu = es * torch::matmul(w, m.mean.to(torch::kFloat64));                          // [L]
  const torch::Tensor M = es2 * (w.view({K, 1, 1}) * m.second.to(torch::kFloat64)).sum(0);             // [L, L]
  torch::Tensor cov = M - torch::outer(mu, mu);
  cov = 0.5 * (cov + cov.t());
  SpectralPrior p;
  p.mean = mu;
  p.covariance = cov;
  p.noise_var = noise_var;
  return p;
}

}  // namespace hsd::model
