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
  m.occlusion = cfg.compositing == Compositing::occlusion;
  m.noise.std_max = cfg.noise_std;
  m.noise.std_min = cfg.noise_std_min;
  m.noise.photons_at_saturation = cfg.photons_at_saturation;
  m.noise.saturation = cfg.saturation;
  m.noise.bit_depth = cfg.bit_depth;
  return m;
}

SensorImage simulate_sensor(const PsfSimulator& psf_sim, const SensorModel& model, const torch::Tensor& height_m,
                            const torch::Tensor& radiance, const torch::Tensor& depth_m,
                            const NoiseRng& noise_rng, const LeaveOut& leave, const PsfProvider& psf_provider) {
  const auto& spec = psf_sim.spec();
  const int64_t L = int64_t(spec.wavelengths_m.size());
  if (radiance.dim() != 4 || radiance.size(1) != L)
    throw InputError("radiance must be [B, " + std::to_string(L) + ", H, W], got " + c10::str(radiance.sizes()));
  check_finite(radiance, "scene radiance");
  check_finite(height_m, "DOE height map (input of the sensor simulation)");
  const int64_t B = radiance.size(0), H = radiance.size(2), W = radiance.size(3), r = spec.psf_size / 2;
  // Work only where used pixels need it: their bounding box plus the reach of
  // the PSF and of the mask blur (those pixels are then exact).
  int64_t y0 = 0, y1 = H, x0 = 0, x1 = W;
  if (leave.valid.defined()) {
    if (leave.valid.dim() != 4 || leave.valid.size(0) != B || leave.valid.size(1) != 1 || leave.valid.size(2) != H ||
        leave.valid.size(3) != W)
      throw InputError("valid map must be [B, 1, H, W] like the radiance, got " + c10::str(leave.valid.sizes()));
    const torch::Tensor v = (leave.valid.detach() > 0.5).cpu();
    const torch::Tensor rows = v.any(3).any(1).any(0).nonzero(), cols = v.any(2).any(1).any(0).nonzero();
    if (rows.numel() == 0) {  // no pixel is used: nothing to render
      y0 = y1 = x0 = x1 = 0;
    } else {
      const int64_t blur = model.mask_sigma_px > 0 ? std::max<int64_t>(1, int64_t(std::ceil(3.0 * model.mask_sigma_px))) : 0;
      const int64_t margin = r + blur + 1;
      y0 = std::max<int64_t>(0, rows.min().item<int64_t>() - margin), y1 = std::min(H, rows.max().item<int64_t>() + 1 + margin);
      x0 = std::max<int64_t>(0, cols.min().item<int64_t>() - margin), x1 = std::min(W, cols.max().item<int64_t>() + 1 + margin);
    }
  }
  // When no PSF is needed, a provider is still called (its collectives, forward
  // and backward, run on every rank) and its output joins the graph as a zero.
  auto provider_link = [&](const std::vector<int64_t>& layers) {
    return psf_provider ? psf_provider(height_m, layers, {}).sum() : torch::zeros({}, height_m.options());
  };
  if (y1 == y0 || x1 == x0) {
    const torch::Tensor link = provider_link({});
    SensorImage out;
    out.clean = torch::zeros({B, 3, H, W}, radiance.options()) * (height_m.sum() + link).to(radiance.scalar_type());  // keeps the graph
    out.image = apply_sensor_noise(out.clean, model.noise, noise_rng);
    out.psf = torch::zeros({int64_t(spec.wavelengths_m.size()), 0, spec.psf_size, spec.psf_size}, radiance.options());
    return out;
  }
  const torch::Tensor rad = radiance.narrow(2, y0, y1 - y0).narrow(3, x0, x1 - x0);
  const torch::Tensor dep = depth_m.narrow(2, y0, y1 - y0).narrow(3, x0, x1 - x0);

  SensorImage out;
  if (leave.layers) {
    out.layers = occupied_layers(dep, spec.depths_m);
  } else {
    for (int64_t z = 0; z < int64_t(spec.depths_m.size()); ++z) out.layers.push_back(z);
  }
  if (leave.bands) {
    out.bands = needed_bands(rad, model.omega, leave.band_tol);
  } else {
    for (int64_t l = 0; l < L; ++l) out.bands.push_back(l);
  }
  std::vector<double> layer_depths;
  for (int64_t z : out.layers) layer_depths.push_back(spec.depths_m[size_t(z)]);
  const auto dt = radiance.scalar_type();
  const torch::Tensor masks = layer_masks(dep.to(dt), layer_depths, model.mask_sigma_px);
  torch::Tensor clean;
  if (out.bands.empty()) {
    const torch::Tensor link = provider_link(out.layers);
    out.psf = torch::zeros({L, int64_t(out.layers.size()), spec.psf_size, spec.psf_size}, radiance.options());
    clean = torch::zeros({B, 3, y1 - y0, x1 - x0}, radiance.options()) * (height_m.sum() + link).to(dt);  // keeps the graph
  } else {
    torch::Tensor psf = (psf_provider ? psf_provider(height_m, out.layers, out.bands)
                                      : psf_sim.compute(height_m, out.layers, {}, out.bands).psf)
                            .to(dt);  // [L', Z', P, P]
    const bool grad = height_m.requires_grad() && torch::GradMode::is_enabled();
    if (leave.psf_crop_tol > 0.0 && !grad) {
      const int64_t w = psf_support_window(psf, leave.psf_crop_tol), o = (spec.psf_size - w) / 2;
      if (w < spec.psf_size) psf = psf.narrow(2, o, w).narrow(3, o, w);
    }
    const torch::Tensor bi = torch::tensor(out.bands, torch::kInt64).to(radiance.device());
    const torch::Tensor rb = rad.index_select(1, bi), ob = model.omega.to(dt).index_select(1, bi);
    clean = model.occlusion ? render_sensor_image_occlusion(rb, masks, psf, ob, layer_depths)
                            : render_sensor_image(rb, masks, psf, ob);
    out.psf = torch::zeros({L, psf.size(1), psf.size(2), psf.size(3)}, psf.options()).index_copy(0, bi, psf);
  }
  if (y0 != 0 || x0 != 0 || y1 != H || x1 != W)
    clean = torch::constant_pad_nd(clean, {x0, W - x1, y0, H - y1}, 0.0);
  out.clean = clean;
  out.image = apply_sensor_noise(out.clean, model.noise, noise_rng);
  check_finite(out.image, "sensor image");
  return out;
}

}  // namespace hsd::optics
