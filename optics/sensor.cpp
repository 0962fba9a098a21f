#include "optics/sensor.h"

#include <torch/torch.h>

#include "common/error.h"
#include "optics/sensor_image.h"
#include "optics/spectrum.h"

namespace hsd::optics {

SensorModel make_sensor_model(const SensorConfig& cfg, const PsfSpec& spec, double band_width_m) {
  SensorModel m;
  m.omega = camera_response(cfg.camera, spec.wavelengths_m, band_width_m).to(spec.device);
  m.mask_sigma_px = cfg.mask_sigma_px;
  m.occlusion = cfg.compositing == "occlusion";
  m.noise.std_max = cfg.noise_std;
  m.noise.std_min = cfg.noise_std_min;
  m.noise.photons_at_saturation = cfg.photons_at_saturation;
  m.noise.saturation = cfg.saturation;
  m.noise.bit_depth = cfg.bit_depth;
  return m;
}

SensorImage simulate_sensor(const PsfSimulator& psf_sim, const SensorModel& model, const torch::Tensor& height_m,
                            const torch::Tensor& radiance, const torch::Tensor& depth_m,
                            c10::optional<at::Generator> generator) {
  const auto& spec = psf_sim.spec();
  if (radiance.dim() != 4 || radiance.size(1) != int64_t(spec.wavelengths_m.size()))
    throw InputError("radiance must be [B, " + std::to_string(spec.wavelengths_m.size()) + ", H, W], got " +
                     c10::str(radiance.sizes()));
  check_finite(radiance, "scene radiance");
  SensorImage out;
  out.layers = occupied_layers(depth_m, spec.depths_m);
  std::vector<double> layer_depths;
  for (int64_t z : out.layers) layer_depths.push_back(spec.depths_m[size_t(z)]);
  out.psf = psf_sim.compute(height_m, out.layers).psf.to(radiance.scalar_type());
  const torch::Tensor masks = layer_masks(depth_m.to(radiance.scalar_type()), layer_depths, model.mask_sigma_px);
  out.clean = model.occlusion ? render_sensor_image_occlusion(radiance, masks, out.psf, model.omega, layer_depths)
                              : render_sensor_image(radiance, masks, out.psf, model.omega);
  out.image = apply_sensor_noise(out.clean, model.noise, generator);
  check_finite(out.image, "sensor image");
  return out;
}

}  // namespace hsd::optics
