#include "data/real_test_set.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/band_resample.h"
#include "data/image_io.h"
#include "data/mat_file.h"
#include "data/preview.h"
#include "data/ray_cast.h"
#include "data/reflectance_library.h"
#include "data/rgbd_import.h"
#include "data/texture_bank.h"
#include "optics/spectrum.h"

namespace hsd::data {

namespace {
const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
constexpr int64_t kCavePx = 2;  // scene pixels per CAVE pixel: the 101-px cube keeps its detail

struct Placement {
  std::string name, what;
  double z_ref;         // depth at the frame centre [m]
  double yaw_deg = 0;   // rotation of the plane about the vertical axis
  double pitch_deg = 0; // about the horizontal axis
};

SpectralScene cave_on_plane(const torch::Tensor& cube, const GeneratorConfig& g, const std::vector<double>& wl,
                            const Placement& p) {
  using namespace raycast;
  // kCavePx scene pixels per cube pixel, square frame; the field of view is cut so a
  // pixel subtends the same angle as in the generator's frame.
  const int64_t H = kCavePx * cube.size(1), W = kCavePx * cube.size(2);
  const double fov = 2.0 * std::atan(std::tan(0.5 * g.fov_deg * M_PI / 180) * double(W) / double(g.width_px)) * 180 / M_PI;
  const Rays r = make_rays(H, W, fov);
  const double a = p.yaw_deg * M_PI / 180, b = p.pitch_deg * M_PI / 180;
  const std::array<double, 3> n{std::sin(a) * std::cos(b), std::sin(b), std::cos(a) * std::cos(b)};
  const Hit h = hit_plane(r, n, n[2] * p.z_ref);  // passes through (0, 0, z_ref)
  const torch::Tensor hit = torch::isfinite(h.t) & (h.t > 0);
  const torch::Tensor t = torch::where(hit, h.t, torch::full_like(h.t, p.z_ref));
  // In-plane coordinates (metres) along u = (cos a, 0, -sin a) and v = n × u, from (0, 0, z_ref).
  const torch::Tensor px = t * r.dx, py = t * r.dy, pz = t - p.z_ref;
  const std::array<double, 3> u{std::cos(a), 0.0, -std::sin(a)};
  const std::array<double, 3> v{n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]};
  const torch::Tensor su = px * u[0] + py * u[1] + pz * u[2];
  const torch::Tensor sv = (px * v[0] + py * v[1] + pz * v[2]) * (v[1] < 0 ? -1.0 : 1.0);  // rows grow downward
  // The cube, cropped to the frame's aspect, fills the frame at z_ref.
  const int64_t cw = cube.size(2), ch = cube.size(1);
  const double frame_aspect = double(W) / double(H);
  const double crop_w = std::min(double(cw), double(ch) * frame_aspect), crop_h = crop_w / frame_aspect;
  const double metres_per_cube_px = 2.0 * r.tan_h * p.z_ref / crop_w;
  const torch::Tensor x = su / metres_per_cube_px + 0.5 * double(cw - 1);
  const torch::Tensor y = sv / metres_per_cube_px + 0.5 * double(ch - 1);
  (void)crop_h;
  SpectralScene s;
  s.wavelengths_m = wl;
  s.kind = SpectralKind::Reflectance;
  s.spectral = sample_mirrored(cube, x, y).clamp(0.0, 1.0).to(torch::kFloat32);
  const torch::Tensor depth = t.clamp(g.depth_min_m, g.depth_max_m);
  s.depth_m = depth.to(torch::kFloat32).unsqueeze(0);
  s.mask = (hit & (t >= g.depth_min_m) & (t <= g.depth_max_m)).to(torch::kFloat32).unsqueeze(0);
  return s;
}
}  // namespace

std::string cave_balloons_path() { return optics::data_dir() + "/real/cave_balloons/balloons_101_101_31.mat"; }

SpectralScene load_cave_balloons(const std::vector<double>& wavelengths_m, double band_width_m) {
  const std::string path = cave_balloons_path();
  const MatFile f = read_mat_file(path);
  const torch::Tensor omsi = f.at("Omsi").tensor();  // [rows, cols, 31]
  if (omsi.dim() != 3 || omsi.size(2) != 31) input_error(path, "'Omsi' must be rows x cols x 31 bands");
  std::vector<double> in_m;
  for (int k = 0; k < 31; ++k) in_m.push_back((400.0 + 10.0 * k) * 1e-9);  // CAVE: band k at 400 + 10 k nm
  const torch::Tensor R = band_resampling_matrix(in_m, wavelengths_m, band_width_m, path);  // [L, 31]
  const int64_t h = omsi.size(0), w = omsi.size(1);
  SpectralScene s;
  s.wavelengths_m = wavelengths_m;
  s.kind = SpectralKind::Reflectance;
  s.spectral = R.mm(omsi.reshape({h * w, 31}).t()).reshape({-1, h, w}).clamp(0.0, 1.0).to(torch::kFloat32);
  s.depth_m = torch::ones({1, h, w}, torch::kFloat32);
  s.mask = torch::ones({1, h, w}, torch::kFloat32);
  return s;
}

SceneRealism cave_realism(const RealismSpec& spec) {
  return measure_realism(load_cave_balloons(spec.wavelengths_m, spec.band_width_m), spec, "CAVE balloons (reference)",
                         /*has_depth=*/false);
}

Manifest generate_real_test_set(const Config& cfg, const std::string& dir) {
  const auto& g = cfg.data.generator;
  const std::vector<double> bands = cfg.optics.wavelengths_m();
  const double bw = cfg.optics.band_width_m();
  const SpectralScene cave = load_cave_balloons(bands, bw);  // read before any output
  const ReflectanceLibrary lib(bands, bw);
  const torch::Tensor d65 = optics::illuminant_bands("D65", bands, bw);
  const double zn = g.depth_min_m, zf = g.depth_max_m;
  // Depths evenly spread in inverse depth over the range (ends excluded), and slanted planes.
  auto at = [&](double q) { return 1.0 / (1.0 / zf + q * (1.0 / zn - 1.0 / zf)); };
  const std::vector<Placement> places{
      {"cave_front_far", "fronto-parallel", at(0.1)},   {"cave_front_mid", "fronto-parallel", at(0.4)},
      {"cave_front_near", "fronto-parallel", at(0.7)},  {"cave_front_nearest", "fronto-parallel", at(0.9)},
      {"cave_slant_yaw", "slanted 45° about the vertical", at(0.4), 45.0, 0.0},
      {"cave_slant_pitch", "slanted 40° about the horizontal", at(0.4), 0.0, -40.0},
      {"cave_slant_both", "slanted 35°/30°", at(0.55), -35.0, 30.0}};
  make_dirs(dir);
  std::filesystem::remove(dir + "/manifest.json");
  Manifest m;
  m.wavelengths_nm = cfg.optics.wavelengths_nm;
  m.band_width_nm = bw * 1e9;
  const RealismSpec rspec = with_band_weights({bands, bw, cfg.sensor.camera, zn, zf, 8});
  std::vector<SceneRealism> realism;
  auto write = [&](const std::string& name, const SpectralScene& s, const std::string& notes) {
    write_scene_exr(dir + "/" + name + ".exr", s, g.half);
    write_srgb_png(dir + "/" + name + "_srgb.png", spectral_to_linear_srgb(s.spectral, bands, bw, d65));
    write_depth_png(dir + "/" + name + "_depth.png", s.depth_m, s.mask, zn, zf);
    m.scenes.push_back({name + ".exr", "test", notes});
    realism.push_back(measure_realism(s, rspec, name));
  };
  log::Progress progress("real-derived scenes", long(places.size() + 1));
  for (const auto& p : places) {
    const SpectralScene s = cave_on_plane(cave.spectral.to(torch::kFloat64), g, bands, p);
    char buf[300];
    std::snprintf(buf, sizeof buf, "real-derived: the CAVE balloons cube (measured reflectance, Yasuma et al. 2010) on a %s plane at %.2f m; geometry synthetic",
                  p.what.c_str(), p.z_ref);
    write(p.name, s, buf);
    progress.step();
  }
  {  // The Middlebury Aloe: real geometry, lifted spectra; scaled to the generator's height.
    RgbdImport in;
    in.rgb_path = optics::data_dir() + "/real/middlebury2006_aloe/aloeL.jpg";
    in.disparity_path = optics::data_dir() + "/real/middlebury2006_aloe/aloeGT.png";
    in.near_m = std::max(zn, at(0.8));
    in.far_m = at(0.15);
    in.scale = std::min(double(g.width_px) / 1282.0, double(g.height_px) / 1110.0);
    std::string notes;
    const SpectralScene s = import_rgbd(in, lib, bands, bw, &notes);
    write("aloe", s, notes);
    progress.step();
  }
  progress.finish();
  const RealismSummary sum = summarise_realism(std::move(realism));
  const SceneRealism ref = cave_realism(rspec);
  write_text_file(dir + "/realism.json", realism_json(sum, &ref).dump(2) + "\n");
  write_text_file(dir + "/realism.md", realism_markdown(sum, &ref));
  write_manifest(dir, m);
  return m;
}

}  // namespace hsd::data
