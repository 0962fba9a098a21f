// hsd_psf: a DOE (optics.doe.init) -> the hyperspectral-depth PSF stack.
// Writes DIR/psf.pt (docs/formats.md), DIR/psf_atlas.png, DIR/config.json and
// prints the energy-in-window table and any sampling warnings.
#include <cmath>
#include <cstdio>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/log.h"
#include "common/text_format.h"
#include "common/tensor_io.h"
#include "optics/depth_distinctness.h"
#include "optics/doe.h"
#include "optics/off_axis_psf.h"
#include "optics/psf.h"
#include "optics/psf_calibration.h"
#include "optics/psf_file.h"
#include "optics/sampling_check.h"
#include "optics/spectrum.h"
#include "viz/psf_atlas.h"
#include "usage/hsd_psf.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

void print_energy_table(const torch::Tensor& e, const optics::PsfSpec& spec) {
  std::string line = "energy in window [%]\n  lambda\\z ";
  char buf[64];
  for (double z : spec.depths_m) {
    std::snprintf(buf, sizeof buf, "%8.3g", z);
    line += buf;
  }
  auto a = e.accessor<double, 2>();
  for (int64_t l = 0; l < e.size(0); ++l) {
    std::snprintf(buf, sizeof buf, "\n  %4.0f nm  ", spec.wavelengths_m[size_t(l)] * 1e9);
    line += buf;
    for (int64_t z = 0; z < e.size(1); ++z) {
      std::snprintf(buf, sizeof buf, "%8.1f", 100.0 * a[l][z]);
      line += buf;
    }
  }
  log::info(line);
}

// optics.field_angle_deg != 0: the off-axis PSFs (optics/off_axis_psf.h) and
// their shift variance against the on-axis ones of the same model: relative L1
// after the off-axis slice is moved (sub-pixel) onto the on-axis slice's centroid.
int run_off_axis(const AppArgs& args, const Config& cfg, const optics::PsfSpec& spec, const torch::Tensor& height) {
  const double th = cfg.optics.field_angle_deg * M_PI / 180.0;
  log::info("off-axis point source at " + c10::str(cfg.optics.field_angle_deg) + " degrees: the window is centred on the chief ray's "
            "image point, " + c10::str(-spec.sensor_distance_m * std::tan(th) / spec.pixel_pitch_m) + " px from the axis; "
            "neglected third-order phase of the tilted Fresnel model " + c10::str(optics::off_axis_neglected_phase_rad(spec, th)) + " rad");
  const torch::Tensor off = optics::off_axis_psf(spec, height, th), on = optics::off_axis_psf(spec, height, 0.0);
  const int64_t L = off.size(0), Z = off.size(1), P = off.size(2);
  torch::Tensor d = torch::zeros({L, Z}, torch::kFloat64), cen = torch::zeros({L, Z, 2}, torch::kFloat64);
  for (int64_t l = 0; l < L; ++l)
    for (int64_t z = 0; z < Z; ++z) {
      const auto co = optics::image_centroid(off[l][z]), cn = optics::image_centroid(on[l][z]);
      cen[l][z][0] = co.first - double(P / 2), cen[l][z][1] = co.second - double(P / 2);
      torch::Tensor moved = optics::fourier_shift(off[l][z], cn.first - co.first, cn.second - co.second);
      moved = moved / moved.sum();
      d[l][z] = ((moved - on[l][z]).abs().sum() / on[l][z].sum()).item<double>();
    }
  std::string table = "shift variance: relative L1 between the off-axis and the on-axis PSF after re-centring (bands in rows, depths in columns)";
  char buf[64];
  for (int64_t l = 0; l < L; ++l) {
    std::snprintf(buf, sizeof buf, "\n  %4.0f nm ", spec.wavelengths_m[size_t(l)] * 1e9);
    table += buf;
    for (int64_t z = 0; z < Z; ++z) {
      std::snprintf(buf, sizeof buf, " %6.3f", d[l][z].item<double>());
      table += buf;
    }
  }
  log::info(table);
  std::snprintf(buf, sizeof buf, "mean %.4f, max %.4f", d.mean().item<double>(), d.max().item<double>());
  log::info(std::string("shift variance ") + buf);
  Json j;
  auto nested = [&](const torch::Tensor& t) {
    Json a = Json::array();
    for (int64_t l = 0; l < L; ++l) {
      Json row = Json::array();
      for (int64_t z = 0; z < Z; ++z)
        row.push_back(t.dim() == 2 ? Json(t[l][z].item<double>()) : Json{t[l][z][0].item<double>(), t[l][z][1].item<double>()});
      a.push_back(row);
    }
    return a;
  };
  j["field_angle_deg"] = cfg.optics.field_angle_deg;
  j["rel_l1"] = nested(d);
  j["rel_l1_mean"] = d.mean().item<double>();
  j["rel_l1_max"] = d.max().item<double>();
  j["centroid_offset_px"] = nested(cen);
  j["window_centre_px_from_axis"] = -spec.sensor_distance_m * std::tan(th) / spec.pixel_pitch_m;
  j["neglected_phase_rad"] = optics::off_axis_neglected_phase_rad(spec, th);
  j["wavelengths_nm"] = cfg.optics.wavelengths_nm;
  j["depths_m"] = cfg.optics.depths_m;
  j["_note"] = "Off-axis PSF (optics/off_axis_psf.h, tilted Fresnel model, midpoint pupil cells) against the on-axis PSF of the same "
               "model: rel_l1 after moving the off-axis slice onto the on-axis slice's centroid; centroid_offset_px: the off-axis "
               "PSF's centroid in its window (row, col), whose centre is the chief ray's image point.";
  const torch::Tensor omega = optics::camera_response(cfg.sensor.camera, spec.wavelengths_m, cfg.optics.band_width_m());
  TensorDict entries = optics::psf_file_entries(spec, off, height, omega);
  entries["field_angle_deg"] = torch::tensor(cfg.optics.field_angle_deg, torch::kFloat64);
  optics::write_psf_file(args.out_dir + "/psf.pt", entries, "simulated");
  write_text_file(args.out_dir + "/shift_variance.json", j.dump(2) + "\n");
  viz::write_psf_atlas(args.out_dir + "/psf_atlas.png", off, spec.wavelengths_m, spec.depths_m);
  write_resolved_config(cfg, args.out_dir);
  log::info("wrote " + args.out_dir + "/psf.pt (off-axis), shift_variance.json, psf_atlas.png, config.json");
  return 0;
}

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  const torch::Device device = resolve_device(cfg.device);
  const auto material = optics::Material::load(cfg.optics.material);
  optics::Doe doe = optics::make_doe(cfg.optics, material, cfg.seed, device);  // reads DOE files: may fail
  const torch::Tensor height = doe.height().detach();
  setup_threads(cfg.threads);  // inputs are checked: from here on, progress output
  make_dirs(args.out_dir);
  const optics::PsfSpec spec = optics::make_psf_spec(cfg.optics, material, device);

  std::string nodes;
  for (int n : spec.pixel_nodes) nodes += std::to_string(n) + " ";
  log::info("DOE: " + choice_word(cfg.optics.doe.init, cfg.optics.doe.init_path) + ", " + std::to_string(spec.doe_samples) + "x" + std::to_string(spec.doe_samples) +
            " samples, max height " + std::to_string(doe.max_height_m() * 1e6) + " um; pixel quadrature nodes per band: " + nodes);

  if (cfg.optics.field_angle_deg != 0.0) return run_off_axis(args, cfg, spec, height);
  const optics::PsfSimulator sim(spec);
  optics::PsfStack out;
  {
    torch::NoGradGuard no_grad;
    log::Progress progress("PSF", int64_t(spec.wavelengths_m.size()));
    out = sim.compute(height, {}, [&](int64_t) { progress.step(); });
  }
  const torch::Tensor energy = out.energy_in_window.cpu();
  print_energy_table(energy, spec);
  const auto report = optics::check_sampling(spec, energy, cfg.optics.energy_warn_threshold);
  for (const auto& w : report.warnings) log::warn(w);
  log::info("largest phase step of the sampled chirps: " + std::to_string(report.max_phase_step_rad.max().item<double>()) +
            " rad per DOE sample (limit pi)");

  const torch::Tensor omega = optics::camera_response(cfg.sensor.camera, spec.wavelengths_m, cfg.optics.band_width_m());
  if (spec.depths_m.size() >= 2) {
    // Per band, and per camera channel (the sensor sums the bands with the camera's response, which can wash out a
    // cue that every band carries, e.g. a PSF that rotates with depth at a different rate per wavelength).
    const torch::Tensor rgb = optics::camera_channel_mean(out.psf, omega);  // [C, Z, P, P]
    const char* channel[] = {"R", "G", "B"};
    auto cue_lines = [&](const torch::Tensor& psf, const std::string& title, auto label) {
      const auto dd = optics::depth_distinctness(psf);
      std::string line = title;
      char buf[128];
      for (size_t l = 0; l < dd.per_band.size(); ++l) {
        std::snprintf(buf, sizeof buf, "\n  %7s  %.3f  (%.3g m vs %.3g m)", label(l).c_str(), dd.per_band[l],
                      spec.depths_m[size_t(dd.pair[l].first)], spec.depths_m[size_t(dd.pair[l].second)]);
        line += buf;
      }
      log::info(line);
    };
    cue_lines(out.psf,
              "depth cue per band: smallest total-variation distance between two depths' PSFs (0 = same PSF, 1 = "
              "disjoint)",
              [&](size_t l) { return std::to_string(int(std::lround(spec.wavelengths_m[l] * 1e9))) + " nm"; });
    if (rgb.size(0) == 3) {
      cue_lines(rgb, "depth cue per camera channel (the band PSFs weighted by the camera response)",
                [&](size_t c) { return std::string(channel[c]); });
      // Through a scene, not a point (optics/depth_distinctness.h): what the network can see.
      const auto sc = optics::scene_depth_cue(rgb, cfg.fisher.scene_noise_variance);
      std::string line = "depth cue through a scene per camera channel (a 1/f^2 Gaussian texture, noise " +
                         format_g(cfg.fisher.scene_noise_variance, 3) +
                         " of its variance (fisher.scene_noise_variance): symmetric KL divergence per pixel between "
                         "two depths' images, nats; smallest pair, mean over pairs)";
      char buf[160];
      double mean = 0;
      for (size_t c = 0; c < sc.min_per_slice.size(); ++c) {
        std::snprintf(buf, sizeof buf, "\n        %s  %.4f (%.3g m vs %.3g m)  mean %.4f", channel[c], sc.min_per_slice[c],
                      spec.depths_m[size_t(sc.pair[c].first)], spec.depths_m[size_t(sc.pair[c].second)],
                      sc.mean_per_slice[c]);
        line += buf;
        mean += sc.mean_per_slice[c] / double(sc.min_per_slice.size());
      }
      std::snprintf(buf, sizeof buf, "\n  mean over channels and pairs: %.4f nats per pixel", mean);
      log::info(line + buf);
    }
  }
  TensorDict entries = optics::psf_file_entries(spec, out.psf, height, omega);
  entries["energy_in_window"] = energy.to(torch::kFloat32);
  optics::write_psf_file(args.out_dir + "/psf.pt", entries, "simulated");
  viz::write_psf_atlas(args.out_dir + "/psf_atlas.png", out.psf, spec.wavelengths_m, spec.depths_m);
  write_resolved_config(cfg, args.out_dir);
  log::info("wrote " + args.out_dir + "/psf.pt, psf_atlas.png, config.json");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_psf", kUsage, {}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
