#include "data/spectral_moments.h"

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::data {

SpectralMoments radiance_moments(const std::vector<LoadedScene>& scenes, const torch::Tensor& illuminants,
                                 double intensity_min, double intensity_max) {
  if (!(intensity_min > 0 && intensity_max >= intensity_min))
    throw InputError("radiance_moments: the intensity range must satisfy 0 < min <= max");
  const double lo = intensity_min, hi = intensity_max;
  const double es = 0.5 * (lo + hi), es2 = (lo * lo + lo * hi + hi * hi) / 3.0;  // E[s], E[s²] for s ~ U[lo, hi]
  torch::Tensor s1, s2;  // Σ over pixels of x and x xᵀ, lit
  int64_t n = 0;
  for (const auto& ls : scenes) {
    const auto& sc = ls.scene;
    const int64_t L = sc.spectral.size(0);
    const torch::Tensor valid = sc.mask.reshape({-1}) > 0.5;
    const torch::Tensor x = sc.spectral.reshape({L, -1}).index({torch::indexing::Slice(), valid}).to(torch::kFloat64);
    if (x.size(1) == 0) continue;
    torch::Tensor m = x.sum(1), R = torch::matmul(x, x.t());
    if (sc.kind == SpectralKind::Reflectance) {
      if (!illuminants.defined() || illuminants.size(0) == 0 || illuminants.size(1) != L)
        throw InputError("radiance_moments: " + ls.file + " is a reflectance and needs illuminants [N, " +
                         std::to_string(L) + "]");
      const torch::Tensor e = illuminants.to(torch::kFloat64);             // [N, L]
      m = (e * m.view({1, L})).mean(0);                                    // E_k[e_k ⊙ Σx]
      R = (e.unsqueeze(2) * e.unsqueeze(1) * R.unsqueeze(0)).mean(0);      // E_k[diag(e_k) R diag(e_k)]
    }
    s1 = s1.defined() ? s1 + m : m;
    s2 = s2.defined() ? s2 + R : R;
    n += x.size(1);
  }
  if (n == 0) throw InputError("radiance_moments: no scene has a valid pixel");
  SpectralMoments out;
  out.mean = es * s1 / double(n);
  out.covariance = es2 * s2 / double(n) - torch::outer(out.mean, out.mean);
  out.covariance = 0.5 * (out.covariance + out.covariance.t());
  out.pixels = n;
  return out;
}

ReflectanceMoments reflectance_moments(const std::vector<LoadedScene>& scenes) {
  torch::Tensor s1, s2;
  int64_t n = 0;
  for (const auto& ls : scenes) {
    const auto& sc = ls.scene;
    if (sc.kind != SpectralKind::Reflectance)
      throw InputError(ls.file + ": a radiance scene; the illuminant reader needs reflectance training scenes");
    const int64_t L = sc.spectral.size(0);
    const torch::Tensor valid = sc.mask.reshape({-1}) > 0.5;
    const torch::Tensor x = sc.spectral.reshape({L, -1}).index({torch::indexing::Slice(), valid}).to(torch::kFloat64);
    if (x.size(1) == 0) continue;
    const torch::Tensor m = x.sum(1), R = torch::matmul(x, x.t());
    s1 = s1.defined() ? s1 + m : m;
    s2 = s2.defined() ? s2 + R : R;
    n += x.size(1);
  }
  if (n == 0) throw InputError("reflectance_moments: no scene has a valid pixel");
  ReflectanceMoments out;
  out.mean = s1 / double(n);
  out.second = s2 / double(n);
  out.second = 0.5 * (out.second + out.second.t());
  out.pixels = n;
  return out;
}

}  // namespace hsd::data
