#include "optics/scene_fisher.h"

#include <algorithm>

#include <torch/torch.h>

#include "common/error.h"
#include "optics/depth_distinctness.h"
#include "optics/spectrum.h"

namespace hsd::optics {

torch::Tensor scene_fisher_from_power(const torch::Tensor& power, const std::vector<torch::Tensor>& dpower) {
  const torch::Tensor inv2 = 1.0 / power.clamp_min(1e-300).square();  // P >= σ² > 0 in use; guarded anyway
  const int64_t K = int64_t(dpower.size());
  std::vector<torch::Tensor> rows;
  for (int64_t i = 0; i < K; ++i) {
    std::vector<torch::Tensor> row;
    for (int64_t j = 0; j < K; ++j) row.push_back(0.5 * (dpower[size_t(i)] * dpower[size_t(j)] * inv2).sum());
    rows.push_back(torch::stack(row));
  }
  return torch::stack(rows);
}

torch::Tensor camera_channel_psfs(const FisherGeometry& g, const Material& material, const torch::Tensor& height_m,
                                  const torch::Tensor& inv_depth, const std::vector<double>& wavelengths_nm,
                                  const torch::Tensor& camera_response) {
  const int64_t L = int64_t(wavelengths_nm.size());
  if (camera_response.dim() != 2 || camera_response.size(1) != L)
    throw InputError("scene Fisher information: the camera response must be [C, " + std::to_string(L) + "], got " +
                     c10::str(camera_response.sizes()));
  std::vector<torch::Tensor> psfs;
  for (int64_t l = 0; l < L; ++l) {
    const double w = wavelengths_nm[size_t(l)];
    const double eta0 = material.index(w * 1e-9);
    const double deta = material.index((w + 0.5) * 1e-9) - material.index((w - 0.5) * 1e-9);  // per nm
    psfs.push_back(point_psf(g, height_m, inv_depth, torch::tensor(w, torch::kFloat64), eta0, deta));
  }
  if (!(camera_response.sum(1).min().item<double>() > 0))
    throw InputError("scene Fisher information: a camera channel has no response over the Fisher bands");
  return camera_channel_mean(torch::stack(psfs), camera_response);  // [C, P, P]
}

CrlbReport scene_crlb_report(const FisherGeometry& g, const Material& material, const torch::Tensor& height_m,
                             const FisherSettings& s, const SceneFisherSettings& scene) {
  if (!(scene.noise_variance > 0)) throw InputError("config key fisher.scene_noise_variance: must be > 0");
  if (!(scene.corner_cycles_per_px > 0)) throw InputError("scene Fisher information: the corner frequency must be > 0");
  if (scene.patch_px < 8) throw InputError("config key fisher.scene_patch_px: must be >= 8");
  check_aggregate(s);
  const bool contrast_unknown = std::find(s.nuisance.begin(), s.nuisance.end(), NuisanceParam::N) != s.nuisance.end();
  const bool design = height_m.requires_grad();
  const int64_t N = scene_dft_size(g.window_px);
  const torch::Tensor S = natural_texture_spectrum(N, scene.corner_cycles_per_px, torch::kFloat64);
  const double patch_share = double(scene.patch_px * scene.patch_px) / double(N * N);

  CrlbReport r;
  r.wavelengths_nm = s.wavelengths_nm;
  r.nuisance = contrast_unknown ? std::vector<NuisanceParam>{NuisanceParam::N} : std::vector<NuisanceParam>{};
  for (double z : s.depths_m) r.inv_depths.push_back(1.0 / z);
  const int64_t Z = int64_t(s.depths_m.size());
  std::vector<torch::Tensor> cd, terms;
  std::vector<double> cond;
  for (int64_t zi = 0; zi < Z; ++zi) {
    const torch::Tensor D = torch::tensor(r.inv_depths[size_t(zi)], torch::kFloat64).requires_grad_(true);
    const torch::Tensor a = torch::ones({}, torch::kFloat64).requires_grad_(true);
    const torch::Tensor h = camera_channel_psfs(g, material, height_m, D, s.wavelengths_nm, scene.camera_response);
    const torch::Tensor power = a * S * psf_mtf2(h, N) + scene.noise_variance;  // [C, N, N]
    std::vector<torch::Tensor> params{D};
    if (contrast_unknown) params.push_back(a);
    const auto J = jacobian_by_autograd(power, params, design);
    const torch::Tensor info = scene_fisher_from_power(power, J) * patch_share;
    const Crlb c = crlb_with_nuisance(info, 1);
    r.max_condition = std::max(r.max_condition, c.condition);
    cond.push_back(c.condition);
    cd.push_back(c.crlb[0]);
    terms.push_back(c.crlb[0] / s.inv_depth_spacing);
  }
  set_aggregates(r, torch::stack(terms), s);
  r.crlb_inv_depth = torch::stack(cd).detach().view({1, Z});
  r.crlb_wavelength_nm = torch::zeros({1, Z}, torch::kFloat64);
  r.condition = torch::tensor(cond, torch::kFloat64).view({1, Z});
  return r;
}

}  // namespace hsd::optics
