#include "common/config.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "common/error.h"
#include "common/log.h"

namespace hsd {

namespace {

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

void require_positive(const JsonReader& r, const std::string& key, double v) {
  if (!(v > 0.0)) r.fail(key, "must be > 0, got " + num(v));
}

// Range-checked reads: the value at `key` (v when absent), which must lie
// between lo and hi, each end closed ('[', ']') or open ('(', ')');
// InputError naming the key otherwise, "must be in [lo, hi]" and the note
// (a unit, what an end value means).
double number_in(const JsonReader& r, const std::string& key, double v, char open, double lo, double hi, char close,
                 const std::string& note = "") {
  v = r.get_number(key, v);
  const bool ok = (open == '[' ? v >= lo : v > lo) && (close == ']' ? v <= hi : v < hi);
  if (!ok) r.fail(key, "must be in " + std::string(1, open) + num(lo) + ", " + num(hi) + std::string(1, close) + note);
  return v;
}
int64_t int_in(const JsonReader& r, const std::string& key, int64_t v, int64_t lo, int64_t hi, const std::string& note = "") {
  v = r.get_int(key, v);
  if (v < lo || v > hi) r.fail(key, "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]" + note);
  return v;
}

DoeConfig parse_doe(const JsonReader& r) {
  DoeConfig d;
  d.init = read_choice_or_file(r, "init", d.init, d.init_path, &d.init_path);
  d.max_height_m = r.get_number_or_null("max_height_m", d.max_height_m);
  if (d.max_height_m < 0.0 || d.max_height_m > 1e-3)
    r.fail("max_height_m", "must be in [0, 1e-3] m (0 = one period at the design wavelength), got " + num(d.max_height_m));
  d.design_wavelength_m = r.get_number("design_wavelength_m", d.design_wavelength_m);
  if (!(d.design_wavelength_m >= 100e-9 && d.design_wavelength_m <= 3000e-9))
    r.fail("design_wavelength_m", "must be in [1e-7, 3e-6] m, got " + num(d.design_wavelength_m));
  d.design_depth_m = r.get_number_or_null("design_depth_m", d.design_depth_m);
  if (d.design_depth_m < 0.0) r.fail("design_depth_m", "must be > 0 (or 0 for the middle of depths_m)");
  d.quantization_levels = r.get_int("quantization_levels", d.quantization_levels);
  if (d.quantization_levels < 0 || d.quantization_levels == 1 || d.quantization_levels > 65536)
    r.fail("quantization_levels", "must be 0 (continuous) or in [2, 65536], got " + std::to_string(d.quantization_levels));
  d.spiral_wings = int_in(r, "spiral_wings", d.spiral_wings, 1, 64);
  d.fisher_path = r.get_string("fisher_path", d.fisher_path);
  return d;
}

OpticsConfig parse_optics(const JsonReader& r) {
  OpticsConfig o;
  o.wavelengths_nm = r.get_number_array("wavelengths_nm");
  if (o.wavelengths_nm.empty()) r.fail("wavelengths_nm", "must hold at least one band centre");
  for (size_t i = 0; i < o.wavelengths_nm.size(); ++i) {
    const double w = o.wavelengths_nm[i];
    if (!(w >= 100.0 && w <= 3000.0))
      r.fail("wavelengths_nm", "element " + std::to_string(i) + " = " + num(w) + " nm is outside [100, 3000] nm");
    if (i > 0 && !(w > o.wavelengths_nm[i - 1])) r.fail("wavelengths_nm", "must be strictly increasing");
  }
  o.band_width_nm = r.get_number("band_width_nm", o.band_width_nm);
  if (o.band_width_nm < 0.0) r.fail("band_width_nm", "must be >= 0 (0 = band spacing)");
  o.depths_m = r.get_number_array("depths_m");
  if (o.depths_m.empty()) r.fail("depths_m", "must hold at least one depth");
  for (size_t i = 0; i < o.depths_m.size(); ++i) {
    if (!(o.depths_m[i] > 0.0))
      r.fail("depths_m", "element " + std::to_string(i) + " = " + num(o.depths_m[i]) + " m; depths must be > 0");
    for (size_t j = 0; j < i; ++j)
      if (o.depths_m[j] == o.depths_m[i]) r.fail("depths_m", "depths must be distinct");
  }
  o.sensor_distance_m = r.get_number("sensor_distance_m");
  require_positive(r, "sensor_distance_m", o.sensor_distance_m);
  o.pixel_pitch_m = r.get_number("pixel_pitch_m");
  require_positive(r, "pixel_pitch_m", o.pixel_pitch_m);
  o.aperture_diameter_m = r.get_number("aperture_diameter_m");
  require_positive(r, "aperture_diameter_m", o.aperture_diameter_m);
  o.aperture_shape = read_choice(r, "aperture_shape", o.aperture_shape);
  o.psf_size = r.get_int("psf_size");
  if (o.psf_size < 1 || o.psf_size % 2 == 0 || o.psf_size > 4095)
    r.fail("psf_size", "must be an odd integer in [1, 4095], got " + std::to_string(o.psf_size));
  o.doe_pitch_m = r.get_number("doe_pitch_m", o.doe_pitch_m);
  require_positive(r, "doe_pitch_m", o.doe_pitch_m);
  o.doe_samples = r.get_int("doe_samples", o.doe_samples);
  if (o.doe_samples < 2 || o.doe_samples > 16384)
    r.fail("doe_samples", "must be in [2, 16384], got " + std::to_string(o.doe_samples));
  const double grid = double(o.doe_samples) * o.doe_pitch_m;
  if (o.aperture_diameter_m > grid * (1.0 + 1e-9))
    r.fail("aperture_diameter_m", num(o.aperture_diameter_m) + " m is larger than the DOE grid (doe_samples * doe_pitch_m = " +
                                      num(grid) + " m)");
  o.material = r.get_string("material", o.material);
  o.pixel_quadrature_nodes = r.get_int("pixel_quadrature_nodes", o.pixel_quadrature_nodes);
  if (o.pixel_quadrature_nodes < 0 || o.pixel_quadrature_nodes > 32)
    r.fail("pixel_quadrature_nodes", "must be in [0, 32] (0 = automatic)");
  o.pixel_quadrature_tol = r.get_number("pixel_quadrature_tol", o.pixel_quadrature_tol);
  if (!(o.pixel_quadrature_tol > 0.0 && o.pixel_quadrature_tol < 1.0))
    r.fail("pixel_quadrature_tol", "must be in (0, 1)");
  o.precision = read_choice(r, "precision", o.precision);
  o.psf_backward = read_choice(r, "psf_backward", o.psf_backward);
  o.mft_rank_tol = r.get_number("mft_rank_tol", o.mft_rank_tol);
  if (o.mft_rank_tol < 0.0 || o.mft_rank_tol > 1e-2) r.fail("mft_rank_tol", "must be in [0, 1e-2] (0 = exact)");
  o.pupil_oversampling = int_in(r, "pupil_oversampling", o.pupil_oversampling, 1, 8);
  o.pupil_cell_integration = read_choice(r, "pupil_cell_integration", o.pupil_cell_integration);
  o.spectral_samples = int_in(r, "spectral_samples", o.spectral_samples, 1, 9);
  o.psf_source = read_choice_or_file(r, "psf_source", o.psf_source, o.psf_path, &o.psf_path);
  o.field_angle_deg = r.get_number("field_angle_deg", o.field_angle_deg);
  if (!(std::abs(o.field_angle_deg) < 30.0)) r.fail("field_angle_deg", "must be within 30 degrees of the axis");
  o.energy_warn_threshold = r.get_number("energy_warn_threshold", o.energy_warn_threshold);
  if (!(o.energy_warn_threshold >= 0.0 && o.energy_warn_threshold <= 1.0))
    r.fail("energy_warn_threshold", "must be in [0, 1]");
  if (auto d = r.optional_child("doe")) o.doe = parse_doe(*d);
  return o;
}

// data.generator.layouts: {layout: weight}, at least one weight positive.
std::vector<std::pair<SceneLayout, double>> parse_layouts(const JsonReader& lr, const JsonReader& generator) {
  std::vector<std::pair<SceneLayout, double>> layouts;
  double total = 0;
  for (const auto& k : lr.keys()) {
    SceneLayout layout;
    if (!choice_of(k, &layout)) lr.fail(k, "is not a layout (" + choice_list<SceneLayout>() + ")");
    const double w = lr.get_number(k);
    if (!(w >= 0.0 && w <= 1e6)) lr.fail(k, "must be a weight in [0, 1e6]");
    layouts.emplace_back(layout, w);
    total += w;
  }
  if (!(total > 0.0)) generator.fail("layouts", "needs a positive weight for at least one layout");
  return layouts;
}

GeneratorConfig parse_generator(const JsonReader& r) {
  GeneratorConfig g;
  g.train_scenes = r.get_int("train_scenes", g.train_scenes);
  g.val_scenes = r.get_int("val_scenes", g.val_scenes);
  g.test_scenes = r.get_int("test_scenes", g.test_scenes);
  for (const auto& [k, v] : {std::pair<const char*, int64_t>{"train_scenes", g.train_scenes},
                             {"val_scenes", g.val_scenes}, {"test_scenes", g.test_scenes}})
    if (v < 0 || v > 100000) r.fail(k, "must be in [0, 100000]");
  g.width_px = r.get_int("width_px", g.width_px);
  g.height_px = r.get_int("height_px", g.height_px);
  if (g.width_px < 16 || g.width_px > 8192) r.fail("width_px", "must be in [16, 8192]");
  if (g.height_px < 16 || g.height_px > 8192) r.fail("height_px", "must be in [16, 8192]");
  g.fov_deg = r.get_number("fov_deg", g.fov_deg);
  if (!(g.fov_deg >= 1.0 && g.fov_deg <= 120.0)) r.fail("fov_deg", "must be in [1, 120] degrees");
  g.depth_min_m = r.get_number("depth_min_m", g.depth_min_m);
  g.depth_max_m = r.get_number("depth_max_m", g.depth_max_m);
  if (!(g.depth_min_m > 0.0)) r.fail("depth_min_m", "must be > 0");
  if (!(g.depth_max_m > g.depth_min_m * 1.2))
    r.fail("depth_max_m", "must exceed data.generator.depth_min_m by at least 20 %");
  g.objects_min = r.get_int("objects_min", g.objects_min);
  g.objects_max = r.get_int("objects_max", g.objects_max);
  if (g.objects_min < 0 || g.objects_min > 64) r.fail("objects_min", "must be in [0, 64]");
  if (g.objects_max < g.objects_min || g.objects_max > 64) r.fail("objects_max", "must be in [objects_min, 64]");
  g.colorchecker = r.get_bool("colorchecker", g.colorchecker);
  g.colorchecker_depth_m = r.get_number("colorchecker_depth_m", g.colorchecker_depth_m);
  if (!(g.colorchecker_depth_m > 0.0 && g.colorchecker_depth_m < g.depth_max_m))
    r.fail("colorchecker_depth_m", "must be in (0, data.generator.depth_max_m)");
  g.half = r.get_bool("half", g.half);
  if (auto lr = r.optional_child("layouts")) g.layouts = parse_layouts(*lr, r);
  g.texture_dir = r.get_string("texture_dir", g.texture_dir);
  if (!g.texture_dir.empty() && !std::filesystem::is_directory(g.texture_dir))
    r.fail("texture_dir", "\"" + g.texture_dir + "\" is not a folder (\"\" = the shipped data/textures)");
  g.texture_scale_min = r.get_number("texture_scale_min", g.texture_scale_min);
  g.texture_scale_max = r.get_number("texture_scale_max", g.texture_scale_max);
  if (!(g.texture_scale_min > 0.0 && g.texture_scale_min <= 100.0)) r.fail("texture_scale_min", "must be in (0, 100]");
  if (!(g.texture_scale_max >= g.texture_scale_min && g.texture_scale_max <= 100.0))
    r.fail("texture_scale_max", "must be in [texture_scale_min, 100]");
  g.texture_filter = read_choice(r, "texture_filter", g.texture_filter);
  g.dead_leaves_max_shapes = r.get_int("dead_leaves_max_shapes", g.dead_leaves_max_shapes);
  if (g.dead_leaves_max_shapes < 1 || g.dead_leaves_max_shapes > 1000000) r.fail("dead_leaves_max_shapes", "must be in [1, 1e6]");
  g.dead_leaves_min_radius = r.get_number("dead_leaves_min_radius", g.dead_leaves_min_radius);
  g.dead_leaves_max_radius = r.get_number("dead_leaves_max_radius", g.dead_leaves_max_radius);
  if (!(g.dead_leaves_min_radius > 0.0 && g.dead_leaves_min_radius <= 1.0))
    r.fail("dead_leaves_min_radius", "must be in (0, 1] (a fraction of the smaller image side)");
  if (!(g.dead_leaves_max_radius >= g.dead_leaves_min_radius && g.dead_leaves_max_radius <= 2.0))
    r.fail("dead_leaves_max_radius", "must be in [dead_leaves_min_radius, 2]");
  g.dead_leaves_surface_min_radius = r.get_number("dead_leaves_surface_min_radius", g.dead_leaves_surface_min_radius);
  if (!(g.dead_leaves_surface_min_radius == 0.0 ||
        (g.dead_leaves_surface_min_radius >= g.dead_leaves_min_radius && g.dead_leaves_surface_min_radius <= g.dead_leaves_max_radius)))
    r.fail("dead_leaves_surface_min_radius", "must be 0 (off) or in [dead_leaves_min_radius, dead_leaves_max_radius]");
  g.spectral_exclusion = r.get_number("spectral_exclusion", g.spectral_exclusion);
  if (!(g.spectral_exclusion >= 0.0 && g.spectral_exclusion <= 0.2))
    r.fail("spectral_exclusion", "must be in [0, 0.2] (relative shape distance to a ColorChecker patch)");
  return g;
}

DataConfig parse_data(const JsonReader& d) {
  DataConfig c;
  c.root = d.get_string("root", c.root);
  if (c.root.empty()) d.fail("root", "must not be empty");
  c.generate_if_missing = d.get_bool("generate_if_missing", c.generate_if_missing);
  if (d.has("illuminants")) c.illuminants = d.get_string_array("illuminants");
  if (c.illuminants.empty()) d.fail("illuminants", "needs at least one illuminant name");
  c.intensity_min = d.get_number("intensity_min", c.intensity_min);
  c.intensity_max = d.get_number("intensity_max", c.intensity_max);
  if (!(c.intensity_min > 0.0)) d.fail("intensity_min", "must be > 0");
  if (c.intensity_max < c.intensity_min) d.fail("intensity_max", "must be >= data.intensity_min");
  c.patch_size_px = int_in(d, "patch_size_px", c.patch_size_px, 8, 8192);
  c.render_margin_px = int_in(d, "render_margin_px", c.render_margin_px, -1, 4096, " (-1 = optics.psf_size / 2)");
  c.border_patches = d.get_bool("border_patches", c.border_patches);
  // data.patches (an epoch size) was never read by training, which draws
  // train.batch_size patches per step: still accepted, so configs saved by
  // earlier runs load, with a warning.
  if (d.has("patches")) {
    (void)d.get_int("patches", 0);
    log::warn("config key data.patches does nothing and is ignored (each step draws train.batch_size patches; "
              "hsd_bench data takes --patches)");
  }
  c.loader_threads = int_in(d, "loader_threads", c.loader_threads, 0, 256, " (0 = all cores)");
  if (auto gr = d.optional_child("generator")) c.generator = parse_generator(*gr);
  return c;
}

}  // namespace

std::vector<std::string> default_augmentation_illuminants() {
  std::vector<std::string> v{"A", "D50", "D55", "D65", "D75"};
  for (int i = 1; i <= 12; ++i) v.push_back("FL" + std::to_string(i));
  for (int i = 1; i <= 5; ++i) v.push_back("HP" + std::to_string(i));
  for (int i = 1; i <= 5; ++i) v.push_back("LED-B" + std::to_string(i));
  v.push_back("LED-BH1");
  v.push_back("LED-RGB1");
  return v;
}

std::vector<double> OpticsConfig::wavelengths_m() const {
  std::vector<double> w;
  for (double v : wavelengths_nm) w.push_back(v * 1e-9);
  return w;
}

double OpticsConfig::band_width_m() const {
  if (band_width_nm > 0.0) return band_width_nm * 1e-9;
  if (wavelengths_nm.size() < 2) return 10e-9;
  return (wavelengths_nm.back() - wavelengths_nm.front()) / double(wavelengths_nm.size() - 1) * 1e-9;
}

namespace {

// Every string must be valid UTF-8 (the resolved config is written back as
// JSON): InputError naming the first key whose text is not.
void check_utf8(const Json& j, const std::string& path) {
  if (j.is_string()) {
    try {
      (void)j.dump();
    } catch (const Json::type_error&) {
      input_error("config key " + path, "is not valid UTF-8 text");
    }
  } else if (j.is_object()) {
    for (const auto& it : j.items()) check_utf8(it.value(), path.empty() ? it.key() : path + "." + it.key());
  } else if (j.is_array()) {
    for (size_t i = 0; i < j.size(); ++i) check_utf8(j[i], path + "[" + std::to_string(i) + "]");
  }
}

}  // namespace

namespace {
void parse_fabrication_error(const JsonReader& e, FabricationErrorConfig& E) {
  E.height_scale_error = number_in(e, "height_scale_error", E.height_scale_error, '(', -0.5, 0.5, ')');
  for (auto [k, v] : {std::pair<const char*, double*>{"roughness_rms_m", &E.roughness_rms_m},
                      {"roughness_correlation_m", &E.roughness_correlation_m}, {"edge_blur_m", &E.edge_blur_m},
                      {"misalignment_m", &E.misalignment_m}, {"decentre_m", &E.decentre_m}}) {
    *v = e.get_number(k, *v);
    if (!(*v >= 0.0 && *v < 1e-3)) e.fail(k, "must be in [0, 1e-3) metres");
  }
}
SensorConfig parse_sensor(const JsonReader& s) {
  SensorConfig S;
  S.camera = s.get_string("camera", S.camera);
  S.noise_std = s.get_number("noise_std", S.noise_std);
  if (S.noise_std < 0.0) s.fail("noise_std", "must be >= 0 (0 disables noise)");
  S.noise_std_min = s.get_number_or_null("noise_std_min", S.noise_std_min);
  if (S.noise_std_min > S.noise_std) s.fail("noise_std_min", "must be <= sensor.noise_std");
  S.photons_at_saturation = s.get_number("photons_at_saturation", S.photons_at_saturation);
  if (S.photons_at_saturation < 0.0) s.fail("photons_at_saturation", "must be >= 0 (0 disables shot noise)");
  S.saturation = s.get_number("saturation", S.saturation);
  if (S.saturation < 0.0) s.fail("saturation", "must be >= 0 (0 disables clipping)");
  S.bit_depth = int_in(s, "bit_depth", S.bit_depth, 0, 24, " (0 = no quantization)");
  if (S.bit_depth > 0 && S.saturation == 0.0) s.fail("bit_depth", "quantization needs sensor.saturation > 0");
  S.mask_sigma_px = s.get_number("mask_sigma_px", S.mask_sigma_px);
  if (S.mask_sigma_px < 0.0 || S.mask_sigma_px > 100.0) s.fail("mask_sigma_px", "must be in [0, 100] pixels");
  S.compositing = read_choice(s, "compositing", S.compositing);
  S.illuminant = s.get_string("illuminant", S.illuminant);
  return S;
}

FisherConfig parse_fisher(const JsonReader& f) {
  FisherConfig F;
  F.photons = f.get_number("photons", F.photons);
  if (!(F.photons > 0.0)) f.fail("photons", "must be > 0");
  F.background = f.get_number("background", F.background);
  if (!(F.background >= 0.0)) f.fail("background", "must be >= 0");
  F.window_px = f.get_int("window_px", F.window_px);
  if (F.window_px < 3 || F.window_px > 255 || F.window_px % 2 == 0) f.fail("window_px", "must be odd, in [3, 255]");
  F.pixel_nodes = int_in(f, "pixel_nodes", F.pixel_nodes, 1, 8);
  F.design_samples = f.get_int("design_samples", F.design_samples);
  if (F.design_samples != 0 && (F.design_samples < 16 || F.design_samples > 4096))
    f.fail("design_samples", "must be 0 (the DOE grid) or in [16, 4096]");
  F.wavelength_stride = f.get_int("wavelength_stride", F.wavelength_stride);
  F.depth_stride = f.get_int("depth_stride", F.depth_stride);
  if (F.wavelength_stride < 1) f.fail("wavelength_stride", "must be >= 1");
  if (F.depth_stride < 1) f.fail("depth_stride", "must be >= 1");
  F.basis = read_choice(f, "basis", F.basis);
  F.zernike_modes = int_in(f, "zernike_modes", F.zernike_modes, 1, 200);
  F.start = read_choice(f, "start", F.start);
  F.steps = int_in(f, "steps", F.steps, 0, 100000);
  F.lr = number_in(f, "lr", F.lr, '(', 0.0, 10.0, ')', " micrometres");
  F.nuisance = read_choice_list(f, "nuisance", F.nuisance);
  F.aggregate = read_choice(f, "aggregate", F.aggregate);
  F.aggregate_cap = number_in(f, "aggregate_cap", F.aggregate_cap, '(', 0.0, 1e6, ']');
  F.model = read_choice(f, "model", F.model);
  F.scene_noise_variance = f.get_number("scene_noise_variance", F.scene_noise_variance);
  if (!(F.scene_noise_variance > 0.0 && F.scene_noise_variance <= 1.0))
    f.fail("scene_noise_variance", "must be in (0, 1] (relative to the texture's variance)");
  F.scene_patch_px = int_in(f, "scene_patch_px", F.scene_patch_px, 8, 4096);
  return F;
}

ModelConfig parse_model(const JsonReader& m) {
  ModelConfig M;
  M.base_width = int_in(m, "base_width", M.base_width, 1, 512);
  M.levels = int_in(m, "levels", M.levels, 1, 7);
  M.norm = read_choice(m, "norm", M.norm);
  M.depth_margin = number_in(m, "depth_margin", M.depth_margin, '[', 0.0, 0.5, ']');
  M.head_init = read_choice(m, "head_init", M.head_init);
  M.preinverse = read_choice(m, "preinverse", M.preinverse);
  M.preinverse_reg = number_in(m, "preinverse_reg", M.preinverse_reg, '[', 1e-8, 1e3, ']');
  M.residual = read_choice(m, "residual", M.residual);
  M.spectral_map = read_choice(m, "spectral_map", M.spectral_map);
  M.base_as_input = m.get_bool("base_as_input", M.base_as_input);
  M.defocus_cost = read_choice(m, "defocus_cost", M.defocus_cost);
  M.defocus_cost_gradient = m.get_bool("defocus_cost_gradient", M.defocus_cost_gradient);
  M.fuse_defocus_reader = m.get_bool("fuse_defocus_reader", M.fuse_defocus_reader);
  M.fusion_reader_box_px = int_in(m, "fusion_reader_box_px", M.fusion_reader_box_px, 1, 255);
  if (M.fusion_reader_box_px % 2 == 0)
    m.fail("fusion_reader_box_px", "must be odd, got " + std::to_string(M.fusion_reader_box_px));
  M.fusion_cost_radius_px = int_in(m, "fusion_cost_radius_px", M.fusion_cost_radius_px, 0, 255);
  M.fusion_depth_radius_px = int_in(m, "fusion_depth_radius_px", M.fusion_depth_radius_px, 0, 255);
  M.fusion_guide_eps = number_in(m, "fusion_guide_eps", M.fusion_guide_eps, '(', 0.0, 1e6, ']');
  M.read_illuminant = m.get_bool("read_illuminant", M.read_illuminant);
  M.illuminant_block_px = int_in(m, "illuminant_block_px", M.illuminant_block_px, 1, 4096);
  M.illuminant_effective_blocks = number_in(m, "illuminant_effective_blocks", M.illuminant_effective_blocks, '(', 0.0, 1e9, ']');
  if (M.read_illuminant && M.residual != ResidualBase::spectral_wiener)
    m.fail("read_illuminant", "needs model.residual = \"spectral_wiener\" (the prior it re-weighs)");
  M.edge_prior_weight = number_in(m, "edge_prior_weight", M.edge_prior_weight, '[', 0.0, 1e6, ']');
  M.edge_prior_iterations = int_in(m, "edge_prior_iterations", M.edge_prior_iterations, 1, 1000);
  M.edge_prior_rho_start = number_in(m, "edge_prior_rho_start", M.edge_prior_rho_start, '(', 0.0, 1e12, ']');
  M.edge_prior_rho_factor = number_in(m, "edge_prior_rho_factor", M.edge_prior_rho_factor, '(', 1.0, 1e6, ']');
  M.project_residual = m.get_bool("project_residual", M.project_residual);
  if (M.project_residual && M.residual != ResidualBase::spectral_wiener)
    m.fail("project_residual", "needs model.residual = \"spectral_wiener\" (the filter it projects with)");
  if (M.edge_prior_weight > 0 && M.residual != ResidualBase::spectral_wiener)
    m.fail("edge_prior_weight", "needs model.residual = \"spectral_wiener\" (the cube it sharpens)");
  if (M.fuse_defocus_reader && M.residual != ResidualBase::spectral_wiener)
    m.fail("fuse_defocus_reader", "needs model.residual = \"spectral_wiener\" (the reader's prior and band PSFs)");
  if (M.defocus_cost == DefocusCost::grey && M.preinverse != Preinverse::wiener)
    m.fail("defocus_cost", "\"grey\" needs model.preinverse = \"wiener\" (its PSFs are the pre-inversion's)");
  if (M.defocus_cost == DefocusCost::spectral && M.residual != ResidualBase::spectral_wiener)
    m.fail("defocus_cost", "\"spectral\" needs model.residual = \"spectral_wiener\" (its prior and band PSFs)");
  if (M.defocus_cost_gradient && M.defocus_cost != DefocusCost::spectral)
    m.fail("defocus_cost_gradient", "needs model.defocus_cost = \"spectral\" (the cost volume it lets the gradient through)");
  M.refine_width = int_in(m, "refine_width", M.refine_width, 0, 256, " (0 = one stage)");
  M.depth_bins = int_in(m, "depth_bins", M.depth_bins, 0, 1024, " (0 = a sigmoid head, >= 2 = bins)");
  if (M.depth_bins == 1) m.fail("depth_bins", "must be 0 (a sigmoid head) or >= 2 (bins), got 1");
  if (M.residual == ResidualBase::preinverse && M.preinverse != Preinverse::wiener)
    m.fail("residual", "\"preinverse\" needs model.preinverse = \"wiener\" (got \"" + choice_name(M.preinverse) + "\")");
  if (M.residual == ResidualBase::spectral_wiener && M.spectral_map == SpectralMap::learned)
    m.fail("spectral_map", "\"learned\" maps RGB to bands, and the \"spectral_wiener\" residual base has no such map");
  return M;
}

TrainConfig parse_train(const JsonReader& t) {
  TrainConfig T;
  T.steps = int_in(t, "steps", T.steps, 1, 100000000);
  T.batch_size = int_in(t, "batch_size", T.batch_size, 1, 4096);
  T.lr_net = number_in(t, "lr_net", T.lr_net, '[', 0.0, 1.0, ')');
  T.lr_doe_m = number_in(t, "lr_doe_m", T.lr_doe_m, '[', 0.0, 1e-5, ')', " metres");
  T.warmup_steps = t.get_int("warmup_steps", T.warmup_steps);
  if (T.warmup_steps < 0) t.fail("warmup_steps", "must be >= 0");
  T.decay = read_choice(t, "decay", T.decay);
  T.min_lr_ratio = number_in(t, "min_lr_ratio", T.min_lr_ratio, '[', 0.0, 1.0, ']');
  T.precision = read_choice(t, "precision", T.precision);
  T.clip_grad_norm = t.get_number("clip_grad_norm", T.clip_grad_norm);
  if (T.clip_grad_norm < 0.0) t.fail("clip_grad_norm", "must be >= 0 (0 = off)");
  T.network_context_px = int_in(t, "network_context_px", T.network_context_px, 0, 4096);
  T.ema_decay = number_in(t, "ema_decay", T.ema_decay, '[', 0.0, 1.0, ')');
  T.spectral_wiener_doe_gradient = t.get_bool("spectral_wiener_doe_gradient", T.spectral_wiener_doe_gradient);
  T.preinverse_doe_gradient = t.get_bool("preinverse_doe_gradient", T.preinverse_doe_gradient);
  T.freeze_doe = t.get_bool("freeze_doe", T.freeze_doe);
  T.doe_every = int_in(t, "doe_every", T.doe_every, 1, 1000000, " (1 = the DOE learns at every step)");
  T.doe_adam_beta1 = number_in(t, "doe_adam_beta1", T.doe_adam_beta1, '[', 0.0, 1.0, ')');
  T.base_doe_gradient_scale = number_in(t, "base_doe_gradient_scale", T.base_doe_gradient_scale, '[', 0.0, 1e6, ']');
  T.init_checkpoint = t.get_string("init_checkpoint", T.init_checkpoint);
  if (auto n = t.optional_child("fabrication_noise")) {
    parse_fabrication_error(*n, T.fabrication_noise);
    if (T.fabrication_noise.misalignment_m != 0.0)
      n->fail("misalignment_m", "must be 0 in training (a mask misalignment needs the level masks; sweep it with hsd_fabricate --tolerance)");
    if (T.fabrication_noise.height_scale_error < 0.0) n->fail("height_scale_error", "is the standard deviation of the drawn error here: must be >= 0");
  }
  T.fabrication_noise_ramp_steps = int_in(t, "fabrication_noise_ramp_steps", T.fabrication_noise_ramp_steps, 0, 10000000,
                                          " (0 = the full noise from step 0)");
  T.fabrication_noise_calibrated = t.get_bool("fabrication_noise_calibrated", T.fabrication_noise_calibrated);
  T.loss_alpha = t.get_number("loss_alpha", T.loss_alpha);
  T.loss_beta = t.get_number("loss_beta", T.loss_beta);
  T.loss_gamma = t.get_number("loss_gamma", T.loss_gamma);
  T.depth_loss = read_choice(t, "depth_loss", T.depth_loss);
  T.hs_loss = read_choice(t, "hs_loss", T.hs_loss);
  T.depth_ce_weight = number_in(t, "depth_ce_weight", T.depth_ce_weight, '[', 0.0, 1e6, ']');
  T.first_stage_cube_weight = number_in(t, "first_stage_cube_weight", T.first_stage_cube_weight, '[', 0.0, 1e6, ']');
  for (const auto& [k, v] : {std::pair<const char*, double>{"loss_alpha", T.loss_alpha},
                             {"loss_beta", T.loss_beta}, {"loss_gamma", T.loss_gamma}})
    if (v < 0.0) t.fail(k, "must be >= 0");
  T.val_every = t.get_int("val_every", T.val_every);
  T.val_patches = t.get_int("val_patches", T.val_patches);
  T.checkpoint_every = t.get_int("checkpoint_every", T.checkpoint_every);
  T.log_every = t.get_int("log_every", T.log_every);
  for (const auto& [k, v] : {std::pair<const char*, int64_t>{"val_every", T.val_every}, {"val_patches", T.val_patches},
                             {"checkpoint_every", T.checkpoint_every}, {"log_every", T.log_every}})
    if (v < 1) t.fail(k, "must be >= 1");
  return T;
}

DistributedConfig parse_distributed(const JsonReader& d) {
  DistributedConfig D;
  D.timeout_s = number_in(d, "timeout_s", D.timeout_s, '[', 1.0, 86400.0, ']', " seconds");
  D.bucket_mib = number_in(d, "bucket_mib", D.bucket_mib, '(', 0.0, 4096.0, ']', " MiB");
  D.sync_batch_norm = d.get_bool("sync_batch_norm", D.sync_batch_norm);
  D.split_psf = d.get_bool("split_psf", D.split_psf);
  return D;
}

FabricationConfig parse_fabrication(const JsonReader& f) {
  FabricationConfig F;
  F.levels = f.get_int("levels", F.levels);
  if (F.levels < 2 || F.levels > 256 || (F.levels & (F.levels - 1)) != 0)
    f.fail("levels", "must be a power of two in [2, 256] (log2 K binary masks)");
  F.min_feature_m = number_in(f, "min_feature_m", F.min_feature_m, '[', 0.0, 1e-3, ')', " metres");
  F.cell_name = f.get_string("cell_name", F.cell_name);
  if (F.cell_name.empty() || F.cell_name.size() > 32 ||
      F.cell_name.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_?$") != std::string::npos)
    f.fail("cell_name", "must be 1-32 characters of A-Z, a-z, 0-9, _, ? and $ (GDSII structure names)");
  if (auto e = f.optional_child("error")) parse_fabrication_error(*e, F.error);
  if (auto t = f.optional_child("tolerance")) {
    auto& T = F.tolerance;
    auto sizes = [&](const char* key, std::vector<double>& v, double lo, double hi, const char* unit) {
      if (!t->has(key)) return;
      v = t->get_number_array(key);
      if (v.empty()) t->fail(key, "must list at least one size");
      for (size_t i = 0; i < v.size(); ++i) {
        if (!(v[i] >= lo && v[i] < hi)) t->fail(key, std::string("sizes must be in [") + c10::str(lo) + ", " + c10::str(hi) + ") " + unit);
        if (i > 0 && !(v[i] > v[i - 1])) t->fail(key, "sizes must increase");
      }
    };
    sizes("height_scale_error", T.height_scale_error, 0.0, 0.5, "(relative)");
    sizes("roughness_rms_m", T.roughness_rms_m, 0.0, 1e-3, "metres");
    sizes("misalignment_m", T.misalignment_m, 0.0, 1e-3, "metres");
    sizes("edge_blur_m", T.edge_blur_m, 0.0, 1e-3, "metres");
    sizes("decentre_m", T.decentre_m, 0.0, 1e-2, "metres");
    T.roughness_correlation_m = t->get_number("roughness_correlation_m", T.roughness_correlation_m);
    if (!(T.roughness_correlation_m > 0.0 && T.roughness_correlation_m < 1e-3))
      t->fail("roughness_correlation_m", "must be in (0, 1e-3) metres");
    T.subsamples = t->get_int("subsamples", T.subsamples);
    if (T.subsamples < 1 || T.subsamples > 16) t->fail("subsamples", "must be in [1, 16]");
    T.network = t->get_bool("network", T.network);
    T.calibrated = t->get_bool("calibrated", T.calibrated);
    T.draws = t->get_int("draws", T.draws);
    if (T.draws < 0 || T.draws > 1000) t->fail("draws", "must be in [0, 1000] (0 = off)");
    if (auto n = t->optional_child("draw_scales")) {
      parse_fabrication_error(*n, T.draw_scales);
      if (T.draw_scales.misalignment_m != 0.0) n->fail("misalignment_m", "must be 0 (drawn as train.fabrication_noise draws; sweep it alone instead)");
      if (T.draw_scales.height_scale_error < 0.0) n->fail("height_scale_error", "is the standard deviation of the drawn error here: must be >= 0");
    }
  }
  return F;
}

CalibrationConfig parse_calibration(const JsonReader& k, int64_t psf_size) {
  CalibrationConfig K;
  K.registration = read_choice(k, "registration", K.registration);
  K.background = read_choice(k, "background", K.background);
  K.hot_pixel_sigma = number_in(k, "hot_pixel_sigma", K.hot_pixel_sigma, '[', 3.0, 1e6, ']');
  K.hot_pixel_ratio = number_in(k, "hot_pixel_ratio", K.hot_pixel_ratio, '[', 1.5, 1e6, ']');
  K.min_snr = number_in(k, "min_snr", K.min_snr, '[', 1.0, 1e9, ']');
  if (auto y = k.optional_child("synthetic")) {
    auto& S = K.synthetic;
    S.frame_px = y->get_int("frame_px", S.frame_px);
    if (S.frame_px != 0 && (S.frame_px < psf_size || S.frame_px > 4096))
      y->fail("frame_px", "must be 0 (automatic) or in [optics.psf_size, 4096]");
    S.peak_counts = y->get_number("peak_counts", S.peak_counts);
    if (!(S.peak_counts >= 10.0 && S.peak_counts <= 60000.0)) y->fail("peak_counts", "must be in [10, 60000] counts");
    for (auto [key, v] : {std::pair<const char*, double*>{"background_counts", &S.background_counts},
                          {"dark_counts", &S.dark_counts}, {"read_noise_counts", &S.read_noise_counts}}) {
      *v = y->get_number(key, *v);
      if (!(*v >= 0.0 && *v <= 10000.0)) y->fail(key, "must be in [0, 10000] counts");
    }
    S.hot_pixels = y->get_int("hot_pixels", S.hot_pixels);
    if (S.hot_pixels < 0 || S.hot_pixels > 10000) y->fail("hot_pixels", "must be in [0, 10000]");
    S.exposures = y->get_int("exposures", S.exposures);
    if (S.exposures < 1 || S.exposures > 64) y->fail("exposures", "must be in [1, 64]");
    S.seed = y->get_int("seed", S.seed);
    if (S.seed < 0) y->fail("seed", "must be >= 0");
    if (y->has("axis_offset_px")) {
      S.axis_offset_px = y->get_number_array("axis_offset_px");
      if (S.axis_offset_px.size() != 2 || !(std::abs(S.axis_offset_px[0]) <= 10) || !(std::abs(S.axis_offset_px[1]) <= 10))
        y->fail("axis_offset_px", "must be [row, col], each within 10 px of the frame centre");
    }
  }
  return K;
}

}  // namespace

Config parse_config(const Json& resolved, std::vector<std::string>* unlike_defaults) {
  if (!resolved.is_object()) input_error("config", "must be a JSON object");
  check_utf8(resolved, "");
  JsonReader r(resolved);
  if (unlike_defaults) r.record_unlike_fallback();
  Config c;
  c.resolved = resolved;
  const int64_t seed = r.get_int("seed", 0);
  if (seed < 0) r.fail("seed", "must be >= 0");
  c.seed = uint64_t(seed);
  c.device = read_choice(r, "device", c.device);
  c.threads = int_in(r, "threads", c.threads, 0, 1024, " (0 = all cores)");
  c.optics = parse_optics(r.child("optics"));
  if (auto s = r.optional_child("sensor")) c.sensor = parse_sensor(*s);
  if (auto f = r.optional_child("fisher")) c.fisher = parse_fisher(*f);
  if (auto m = r.optional_child("model")) c.model = parse_model(*m);
  if (auto t = r.optional_child("train")) c.train = parse_train(*t);
  if (auto d = r.optional_child("distributed")) c.distributed = parse_distributed(*d);
  if (auto d = r.optional_child("data")) c.data = parse_data(*d);
  if (auto f = r.optional_child("fabrication")) c.fabrication = parse_fabrication(*f);
  if (auto k = r.optional_child("calibration")) c.calibration = parse_calibration(*k, c.optics.psf_size);
  // The U-Net's bottom must keep a pixel of the patch, and batch norm needs
  // more than one value per channel there (batch x pixels).
  const int64_t bottom = c.data.patch_size_px >> c.model.levels;
  if (bottom < 1 || (c.model.norm == NormKind::batch && c.train.batch_size * bottom * bottom < 2))
    input_error("config key model.levels", std::to_string(c.model.levels) + " poolings leave " + std::to_string(bottom) +
                                               " px of a " + std::to_string(c.data.patch_size_px) +
                                               "-px patch (data.patch_size_px)" +
                                               (bottom < 1 ? std::string("") : " for a batch of one (batch norm needs 2 values)"));
  if (c.train.depth_ce_weight > 0.0 && c.model.depth_bins < 2)
    input_error("config key train.depth_ce_weight", "> 0 needs the bins head (model.depth_bins >= 2, got " +
                                                        std::to_string(c.model.depth_bins) + ")");
  if (c.train.first_stage_cube_weight > 0.0 && c.model.refine_width < 1)
    input_error("config key train.first_stage_cube_weight", "> 0 needs the cube's second stage (model.refine_width >= 1, got " +
                                                                std::to_string(c.model.refine_width) + ")");
  if (c.train.base_doe_gradient_scale != 1.0 && c.model.residual != ResidualBase::spectral_wiener)
    input_error("config key train.base_doe_gradient_scale",
                "!= 1 needs the spectral Wiener base (model.residual = \"spectral_wiener\"), whose path into the DOE it scales");
  r.check_all_used();
  if (unlike_defaults) *unlike_defaults = r.unlike_fallback();
  return c;
}

Config load_config(const std::string& path, const std::vector<std::string>& overrides) {
  Json j = load_json_with_extends(path);
  for (const auto& o : overrides) apply_override(j, o);
  return parse_config(j);
}

}  // namespace hsd
