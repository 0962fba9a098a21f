#include "train/baselines.h"

#include <cmath>
#include <limits>

#include <torch/torch.h>

#include "common/error.h"
#include "data/illuminant_augment.h"
#include "data/spectral_moments.h"
#include "model/spectral_upsampling.h"
#include "model/wiener_preinverse.h"
#include "optics/sensor_image.h"

namespace hsd::train {

double median_inverse_depth(const std::vector<data::LoadedScene>& scenes) {
  std::vector<torch::Tensor> inv;
  for (const auto& s : scenes) {
    const torch::Tensor z = s.scene.depth_m.to(torch::kFloat64).flatten();
    const torch::Tensor valid = (s.scene.mask.flatten() > 0.5) & torch::isfinite(z) & (z > 0);
    inv.push_back(1.0 / z.masked_select(valid));
  }
  const torch::Tensor all = inv.empty() ? torch::empty({0}, torch::kFloat64) : torch::cat(inv);
  if (all.numel() == 0) throw InputError("constant-depth baseline: the training split has no valid depth pixel");
  // The lower median (torch's convention), exact for any count.
  return all.median().item<double>();
}

model::SpectralPrior training_spectral_prior(const std::vector<data::LoadedScene>& train_scenes, const Config& cfg,
                                             const optics::SensorModel& sensor) {
  const data::IlluminantBank bank(cfg.data.illuminants, cfg.optics.wavelengths_m(), cfg.optics.band_width_m());
  const data::SpectralMoments mo =
      data::radiance_moments(train_scenes, bank.spectra(), cfg.data.intensity_min, cfg.data.intensity_max);
  const torch::Tensor omega = sensor.omega.cpu().to(torch::kFloat64);
  const double y_mean = torch::matmul(omega, mo.mean).mean().item<double>();
  const auto& nm = sensor.noise;
  model::SpectralPrior p;
  p.mean = mo.mean.to(torch::kFloat32);
  p.covariance = mo.covariance.to(torch::kFloat32);
  p.noise_var = model::mean_noise_variance(nm.std_min, nm.std_max, nm.photons_at_saturation, y_mean);
  return p;
}

model::IlluminantMoments training_illuminant_moments(const std::vector<data::LoadedScene>& train_scenes, const Config& cfg) {
  const data::IlluminantBank bank(cfg.data.illuminants, cfg.optics.wavelengths_m(), cfg.optics.band_width_m());
  const data::ReflectanceMoments r = data::reflectance_moments(train_scenes);
  return model::illuminant_moments(r.mean, r.second, bank.spectra(), cfg.data.intensity_min, cfg.data.intensity_max);
}

torch::Tensor constant_depth_map(const torch::Tensor& like, double inv_depth_per_m) {
  if (!(inv_depth_per_m > 0)) throw InputError("constant-depth baseline: the inverse depth must be > 0");
  return torch::full_like(like, 1.0 / inv_depth_per_m);
}

torch::Tensor layer_oracle_depth_map(const torch::Tensor& depth_m, const torch::Tensor& mask,
                                     const std::vector<double>& layer_depths_m) {
  if (!depth_m.sizes().equals(mask.sizes()) || depth_m.dim() < 2)
    throw InputError("layer oracle: the depth map and the mask must have the same shape [.., H, W]");
  const int64_t H = depth_m.size(-2), W = depth_m.size(-1), N = depth_m.numel() / (H * W);
  const torch::Tensor d = depth_m.reshape({N, 1, H, W}).to(torch::kFloat64);
  const torch::Tensor v = (mask.reshape({N, 1, H, W}) > 0.5).to(torch::kFloat64);
  const torch::Tensor idx = optics::nearest_layer(d.where(v > 0, torch::ones_like(d)), layer_depths_m);  // [N, 1, H, W]
  const int64_t Z = int64_t(layer_depths_m.size());
  const torch::Tensor onehot = (idx == torch::arange(Z, idx.options()).view({1, Z, 1, 1})).to(torch::kFloat64) * v;
  const torch::Tensor count = onehot.sum({2, 3}, true), total = (onehot * d).sum({2, 3}, true);   // [N, Z, 1, 1]
  const torch::Tensor mean = total / count.clamp_min(1.0);                                            // guarded: empty layers
  const torch::Tensor oracle = (onehot * mean).sum(1, true);                                          // [N, 1, H, W]
  return oracle.where(v > 0, d).to(depth_m.scalar_type()).reshape(depth_m.sizes());
}

double effective_resolution_px(const std::vector<int64_t>& windows, const std::vector<double>& oracle_rmse, double rmse) {
  if (windows.empty() || windows.size() != oracle_rmse.size())
    throw InputError("effective resolution: windows and oracle RMSEs must be non-empty and of equal size");
  if (rmse <= oracle_rmse.front()) return double(windows.front());
  for (size_t i = 1; i < windows.size(); ++i)
    if (rmse <= oracle_rmse[i]) {
      const double a = oracle_rmse[i - 1], b = oracle_rmse[i];
      const double t = b > a ? (rmse - a) / (b - a) : 1.0;
      return std::exp(std::log(double(windows[i - 1])) + t * (std::log(double(windows[i])) - std::log(double(windows[i - 1]))));
    }
  return std::numeric_limits<double>::infinity();
}

torch::Tensor wiener_upsampling_cube(const torch::Tensor& image, const torch::Tensor& rgb_psf, double reg,
                                     const torch::Tensor& upsampling_weights) {
  return model::spectral_upsample(upsampling_weights, wiener_mean_image(image, rgb_psf, reg));
}

torch::Tensor wiener_mean_image(const torch::Tensor& image, const torch::Tensor& rgb_psf, double reg) {
  return model::preinverse_layer_mean(model::wiener_preinverse(image, rgb_psf, reg), rgb_psf.size(0));
}

}  // namespace hsd::train
