// hsd_simulate: a spectral-EXR scene -> the sensor image of the configured DOE.
// Writes DIR/sensor.exr (linear R, G, B float32, same size as the scene),
// DIR/sensor.png (sRGB preview), DIR/psf_atlas.png (the PSFs of the depth
// layers the scene occupies) and DIR/config.json.
#include <chrono>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/band_resample.h"
#include "data/image_io.h"
#include "data/scene_exr.h"
#include "optics/doe.h"
#include "optics/psf.h"
#include "optics/psf_source.h"
#include "optics/sensor.h"
#include "optics/spectrum.h"
#include "viz/psf_atlas.h"
#include "usage/hsd_simulate.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

int run(const AppArgs& args) {
  const std::string scene_path = args.option("--scene", "");
  if (scene_path.empty()) input_error("--scene", "required (a spectral OpenEXR scene)");
  const Config cfg = load_config(args.config_path, args.overrides);
  const torch::Device device = resolve_device(cfg.device);
  const auto t0 = std::chrono::steady_clock::now();
  auto since = [t = t0]() mutable {
    const auto now = std::chrono::steady_clock::now();
    const double s = std::chrono::duration<double>(now - t).count();
    t = now;
    return s;
  };

  const std::vector<double> bands = cfg.optics.wavelengths_m();
  // Other bands are resampled to the config's by band integration (with a warning).
  const data::SpectralScene scene =
      data::resample_scene_bands(data::read_scene_exr(scene_path), bands, cfg.optics.band_width_m(), scene_path);
  if (cfg.optics.field_angle_deg != 0.0)
    input_error("config key optics.field_angle_deg", "is for hsd_psf's off-axis analysis; hsd_simulate images with the "
                                                     "shift-invariant on-axis model (set it to 0)");
  const auto material = optics::Material::load(cfg.optics.material);
  // optics.psf_source: the DOE's PSFs (nullptr), or a fixed stack (a PSF file, the all-in-focus control).
  const optics::PsfProvider fixed = optics::psf_source_provider(cfg.optics, material, device);
  const double t_read = since();
  setup_threads(cfg.threads);  // inputs are checked: from here on, progress output
  make_dirs(args.out_dir);

  torch::Tensor radiance = scene.spectral.unsqueeze(0);  // [1, L, H, W]
  if (scene.kind == data::SpectralKind::Reflectance) {
    const torch::Tensor e = optics::illuminant_bands(cfg.sensor.illuminant, bands, cfg.optics.band_width_m());
    radiance = radiance * e.view({1, -1, 1, 1});
    log::info("reflectance scene lit by " + cfg.sensor.illuminant);
  } else {
    log::info("radiance scene (S0 channels), used as it is");
  }
  // Pixels outside the mask take the farthest layer; they are not evaluated downstream.
  double far = 0.0;
  for (double z : cfg.optics.depths_m) far = std::max(far, z);
  const torch::Tensor depth = torch::where(scene.mask > 0.5, scene.depth_m, torch::full_like(scene.depth_m, far)).unsqueeze(0);

  const optics::PsfSpec spec = optics::make_psf_spec(cfg.optics, material, device);
  const optics::PsfSimulator sim(spec);
  const optics::SensorModel model = optics::make_sensor_model(cfg.sensor, spec, cfg.optics.band_width_m());
  const torch::Tensor height = optics::make_doe(cfg.optics, material, cfg.seed, device).height().detach();
  if (fixed) log::info("imaging through the fixed PSFs of optics.psf_source = " + choice_word(cfg.optics.psf_source, cfg.optics.psf_path));
  auto gen = at::detail::createCPUGenerator(cfg.seed);
  const double t_setup = since();

  torch::NoGradGuard no_grad;
  const optics::SensorImage img =
      optics::simulate_sensor(sim, model, height, radiance.to(device), depth.to(device), gen, optics::LeaveOut(), fixed);
  std::vector<double> used_depths;
  std::string used;
  for (int64_t z : img.layers) {
    used_depths.push_back(spec.depths_m[size_t(z)]);
    used += c10::str(spec.depths_m[size_t(z)]) + " ";
  }
  log::info("depth layers occupied (m): " + used + "(" + std::to_string(img.layers.size()) + " of " +
            std::to_string(spec.depths_m.size()) + "; the others were left out)");

  const double t_image = since();
  const torch::Tensor J = img.image[0].cpu();
  data::write_channels_exr(args.out_dir + "/sensor.exr", J, {"R", "G", "B"});
  data::write_srgb_png(args.out_dir + "/sensor.png", J, cfg.sensor.saturation > 0 ? cfg.sensor.saturation : 1.0);
  viz::write_psf_atlas(args.out_dir + "/psf_atlas.png", img.psf, spec.wavelengths_m, used_depths);
  write_resolved_config(cfg, args.out_dir);
  const double t_write = since();
  log::info("seconds: scene read " + c10::str(t_read) + ", optics set-up " + c10::str(t_setup) + ", PSFs and image " +
            c10::str(t_image) + ", outputs " + c10::str(t_write));
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  log::info("wrote " + args.out_dir + "/sensor.exr, sensor.png, psf_atlas.png, config.json (" +
            std::to_string(J.size(1)) + "x" + std::to_string(J.size(2)) + ", " + c10::str(secs) + " s)");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_simulate", kUsage, {"--scene"}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
