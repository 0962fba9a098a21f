// hsd_bench accuracy --out DIR: error against run time of the simulator's
// discretisation knobs, and what leaving out unneeded work saves.
//
// Every setting computes the config's PSF stack and renders a test scene (a
// generated tabletop scene, --patch pixels) from the same DOE. Its error is
// measured against one converged float64 reference (exact matrix Fourier
// transform, 8×8 Gauss nodes per pixel, pupil oversampling --ref-oversampling,
// --ref-spectral wavelengths per band):
//   psf_rel_l1 = Σ|P − P_ref| / Σ P_ref per (λ, z), worst and mean;
//   sensor_psnr_db = PSNR of the rendered sensor image against the reference's
//   (peak = the reference image's maximum).
// Its cost is the median time of the PSF stack plus the sensor image, forward
// (seconds_fwd) and forward+backward w.r.t. the height map (seconds).
// Knobs: precision, pixel quadrature nodes, the low-rank cut of the window
// kernels (and the exact MFT), pupil oversampling, spectral samples per band,
// the PSF window, and the straightforward FFT + bilinear method.
//
// To keep the float64 reference affordable the study uses every
// --band-stride-th band of the config (both ends kept; band width unchanged).
//
// Writes DIR/error_vs_runtime.csv, DIR/error_vs_runtime.png (Pareto front
// marked), DIR/leave_out.csv and DIR/accuracy.md (recommendations).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>

#include <torch/torch.h>

#include "bench/baseline_psf.h"
#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/text_format.h"
#include "data/band_resample.h"
#include "data/reflectance_library.h"
#include "data/scene_generator.h"
#include "optics/doe.h"
#include "optics/pixel_quadrature.h"
#include "optics/psf.h"
#include "optics/sensor.h"
#include "optics/sensor_image.h"
#include "optics/spectrum.h"
#include "viz/plot.h"

namespace hsd::bench {

namespace {

struct Setting {
  std::string name, knob, value;
  optics::PsfSpec spec;
  bool fft_bilinear = false;  // the straightforward method instead of hsd's
};

struct Row {
  Setting s;
  double seconds = 0, seconds_fwd = 0, rel_l1_max = 0, rel_l1_mean = 0, psnr_db = 0, energy_min = 0;
  double worst_nm = 0, worst_depth_m = 0;  // where the worst PSF error is
};

// Zero-pads a [L, Z, w, w] stack to [L, Z, P, P] (w ≤ P, both odd).
torch::Tensor pad_to(const torch::Tensor& p, int64_t P) {
  const int64_t d = (P - p.size(-1)) / 2;
  return d == 0 ? p : torch::constant_pad_nd(p, {d, d, d, d}, 0.0);
}

double psnr_db(const torch::Tensor& a, const torch::Tensor& ref) {
  const double mse = (a.to(torch::kFloat64) - ref).pow(2).mean().item<double>();
  const double peak = ref.max().item<double>();
  return mse > 0 ? 10.0 * std::log10(peak * peak / mse) : 999.0;
}

// The study's command line.
struct StudyArgs {
  std::string config_path;
  int repeats = 3;
  int64_t patch = 128, stride = 3, ref_os = 4, ref_sp = 5;
};

StudyArgs parse_study_args(const AppArgs& args) {
  if (args.out_dir.empty()) input_error("--out", "required (folder for error_vs_runtime.csv/.png and accuracy.md)");
  StudyArgs a;
  a.config_path = args.config_path.empty() ? std::string("configs/paper.json") : args.config_path;
  a.repeats = int(args.integer("--repeats", 3));
  a.patch = args.integer("--patch", 128), a.stride = args.integer("--band-stride", 3);
  a.ref_os = args.integer("--ref-oversampling", 4), a.ref_sp = args.integer("--ref-spectral", 5);
  if (a.patch < 16 || a.patch > 1024) input_error("--patch", "must be in [16, 1024]");
  if (a.stride < 1) input_error("--band-stride", "must be >= 1");
  if (a.ref_os < 1 || a.ref_os > 8) input_error("--ref-oversampling", "must be in [1, 8]");
  if (a.ref_sp < 1 || a.ref_sp > 9) input_error("--ref-spectral", "must be in [1, 9]");
  return a;
}

// The config's optics on the study's bands: every stride-th band, the last
// one kept, the band width unchanged.
OpticsConfig study_optics(OpticsConfig o, int64_t stride) {
  const double band_width_nm = o.band_width_m() * 1e9;
  std::vector<double> nm;
  for (size_t i = 0; i < o.wavelengths_nm.size(); i += size_t(stride)) nm.push_back(o.wavelengths_nm[i]);
  if (nm.back() != o.wavelengths_nm.back()) nm.push_back(o.wavelengths_nm.back());
  o.wavelengths_nm = nm;
  o.band_width_nm = band_width_nm;
  return o;
}

// What every setting is measured on: the study's spec, the config's DOE and a
// test scene (a generated tabletop scene, lit by the config's illuminant).
struct Study {
  Study(const Config& cfg, const StudyArgs& a)
      : args(a),
        ocfg(study_optics(cfg.optics, a.stride)),
        bands_all(cfg.optics.wavelengths_nm.size()),
        material(optics::Material::load(ocfg.material)),
        base(optics::make_psf_spec(ocfg, material, torch::kCPU)),
        h0(optics::make_doe(ocfg, material, cfg.seed, torch::kCPU).height().detach()),
        L(int64_t(base.wavelengths_m.size())),
        Z(int64_t(base.depths_m.size())),
        P(base.psf_size),
        sensor(optics::make_sensor_model(cfg.sensor, base, base.band_width_m)) {
    const int64_t patch = a.patch;
    GeneratorConfig g = cfg.data.generator;
    g.width_px = std::max<int64_t>(patch, 64), g.height_px = std::max<int64_t>(patch, 64);
    g.depth_min_m = *std::min_element(ocfg.depths_m.begin(), ocfg.depths_m.end());
    g.depth_max_m = *std::max_element(ocfg.depths_m.begin(), ocfg.depths_m.end());
    const data::ReflectanceLibrary lib(base.wavelengths_m, base.band_width_m);
    const auto scene = data::generate_tabletop_scene(g, lib, base.wavelengths_m, cfg.seed + 17).scene;
    spectral = scene.spectral;
    const torch::Tensor illum = optics::illuminant_bands(cfg.sensor.illuminant, base.wavelengths_m, base.band_width_m);
    radiance = lit(illum);
    depth = torch::where(scene.mask > 0.5, scene.depth_m, torch::full_like(scene.depth_m, g.depth_max_m))
                .narrow(1, 0, patch).narrow(2, 0, patch).unsqueeze(0).contiguous();
    layers = optics::occupied_layers(depth, base.depths_m);
    std::vector<double> layer_depths;
    for (int64_t z : layers) layer_depths.push_back(base.depths_m[size_t(z)]);
    masks = optics::layer_masks(depth, layer_depths, sensor.mask_sigma_px);
    zi = torch::tensor(layers, torch::kInt64);
  }
  // The scene under an illuminant [L] -> radiance [1, L, patch, patch].
  torch::Tensor lit(const torch::Tensor& illum) const {
    return (spectral * illum.view({-1, 1, 1})).narrow(1, 0, args.patch).narrow(2, 0, args.patch).unsqueeze(0).contiguous();
  }
  // PSFs of the scene's layers [L, Z', P', P'] -> sensor image J [1, 3, H, W], in the PSF's dtype.
  torch::Tensor render_layers(const torch::Tensor& p) const {
    const auto dt = p.scalar_type();
    return optics::render_sensor_image(radiance.to(dt), masks.to(dt), p, sensor.omega.to(dt));
  }
  // PSFs of every layer [L, Z, P', P'] -> J.
  torch::Tensor render(const torch::Tensor& psf_all) const { return render_layers(psf_all.index_select(1, zi)); }

  StudyArgs args;
  OpticsConfig ocfg;  // the config's optics on the study's bands
  size_t bands_all;
  optics::Material material;
  optics::PsfSpec base;
  torch::Tensor h0;  // the config's DOE height map [N, N] m
  int64_t L, Z, P;
  optics::SensorModel sensor;
  torch::Tensor spectral;               // scene reflectance [L, H, W]
  torch::Tensor radiance, depth, masks;  // [1, L, p, p]; [1, 1, p, p] m; soft masks of the occupied layers
  std::vector<int64_t> layers;          // occupied layers (indices into base.depths_m)
  torch::Tensor zi;                     // the same, as a tensor
};

// The converged reference and a check of its own cell rule.
struct Reference {
  torch::Tensor psf, image;  // [L, Z, P, P] float64, sensor image [1, 3, p, p]
  double seconds = 0;        // time of the reference PSFs
  double rule_check = 0;     // worst change when the midpoint cell rule replaces the reference's
};

Reference compute_reference(const Study& st) {
  optics::PsfSpec ref_spec = optics::converged_reference(st.base);
  ref_spec.pupil_oversampling = st.args.ref_os;
  ref_spec.spectral_samples = st.args.ref_sp;
  if (st.args.ref_sp > 1) ref_spec.spectral_refractive_index = st.material.indices(ref_spec.spectral_wavelengths_m());
  torch::NoGradGuard ng;
  Reference ref;
  log::info("reference: float64, exact MFT, 8x8 pixel nodes, pupil x" + std::to_string(st.args.ref_os) + ", " +
            std::to_string(st.args.ref_sp) + " wavelengths per band, " + std::to_string(st.L) + " bands x " +
            std::to_string(st.Z) + " depths ...");
  log::Progress prog("reference", st.L);
  const auto t0 = std::chrono::steady_clock::now();
  ref.psf = optics::PsfSimulator(ref_spec).compute(st.h0, {}, [&](int64_t) { prog.step(); }).psf;
  ref.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  prog.finish();
  ref.image = st.render(ref.psf);
  // Does the reference favour its own cell rule? The midpoint rule at the same
  // oversampling, at the first and last band.
  optics::PsfSpec mid = ref_spec;
  mid.pupil_cell_integration = CellIntegration::midpoint;
  const std::vector<int64_t> ends{0, st.L - 1};
  const torch::Tensor a = optics::PsfSimulator(mid).compute(st.h0, {}, {}, ends).psf;
  const torch::Tensor b = ref.psf.index_select(0, torch::tensor(ends, torch::kInt64));
  ref.rule_check = ((a - b).abs().sum({2, 3}) / b.sum({2, 3})).max().item<double>();
  log::info("reference check: the midpoint rule at the same oversampling differs by " + format("%.2e", ref.rule_check));
  return ref;
}

// The settings compared: one knob changed from the config's default each.
std::vector<Setting> study_settings(const Study& st, const Config& cfg) {
  const optics::PsfSpec& base = st.base;
  std::vector<Setting> settings;
  auto add = [&](const std::string& name, const std::string& knob, const std::string& value,
                 const std::function<void(optics::PsfSpec&)>& edit) {
    Setting s{name, knob, value, base};
    edit(s.spec);
    if (s.spec.spectral_samples > 1) s.spec.spectral_refractive_index = st.material.indices(s.spec.spectral_wavelengths_m());
    settings.push_back(s);
  };
  add("default", "config", "as configured", [](optics::PsfSpec&) {});
  add("float64", "precision", "float64", [](optics::PsfSpec& s) { s.real_dtype = torch::kFloat64; });
  for (int n : {1, 2, 3, 4})
    add("nodes_" + std::to_string(n), "pixel nodes per axis", std::to_string(n),
        [n](optics::PsfSpec& s) { s.pixel_nodes.assign(s.pixel_nodes.size(), n); });
  for (double tol : {1e-1, 1e-2, 1e-3}) {
    if (tol == cfg.optics.pixel_quadrature_tol && cfg.optics.pixel_quadrature_nodes == 0) continue;
    add("quadrature_tol_" + format("%.0e", tol), "pixel_quadrature_tol", format("%.0e", tol), [tol](optics::PsfSpec& s) {
      for (size_t l = 0; l < s.wavelengths_m.size(); ++l)
        s.pixel_nodes[l] = optics::choose_pixel_nodes(
            optics::intensity_cycles_per_pixel(s.aperture_diameter_m, s.pixel_pitch_m, s.wavelengths_m[l], s.sensor_distance_m), tol);
    });
  }
  for (double tol : {1e-3, 1e-4, 1e-6, 1e-8})
    if (tol != base.mft_rank_tol) add("rank_tol_" + format("%.0e", tol), "mft_rank_tol", format("%.0e", tol), [tol](optics::PsfSpec& s) { s.mft_rank_tol = tol; });
  add("exact_mft", "mft_rank_tol", "0 (exact MFT)", [](optics::PsfSpec& s) { s.mft_rank_tol = 0.0; });
  if (!base.depth_basis)
    add("depth_basis", "depth_basis (training's kernels)", "joint over depths",
        [](optics::PsfSpec& s) { s.depth_basis = true; });
  add("pupil_x2", "pupil_oversampling", "2", [](optics::PsfSpec& s) { s.pupil_oversampling = 2; });
  for (const CellIntegration rule : {CellIntegration::midpoint, CellIntegration::sinc, CellIntegration::sinc_cross})
    if (base.pupil_cell_integration != rule)
      add("cell_" + choice_name(rule), "pupil_cell_integration", choice_name(rule),
          [rule](optics::PsfSpec& s) { s.pupil_cell_integration = rule; });
  for (int k : {1, 2, 3})
    if (k != base.spectral_samples)
      add("spectral_" + std::to_string(k), "spectral_samples", std::to_string(k),
          [k](optics::PsfSpec& s) { s.spectral_samples = k; });
  {
    const int64_t k = std::max<int64_t>(3, base.spectral_samples);
    add("spectral_" + std::to_string(k) + "_pupil_x2", "spectral_samples + pupil_oversampling", std::to_string(k) + " + 2",
        [k](optics::PsfSpec& s) { s.spectral_samples = k, s.pupil_oversampling = 2; });
  }
  const int64_t P = st.P;
  for (int64_t w : {P / 2 | 1, (3 * P / 4) | 1})
    if (w < P) add("window_" + std::to_string(w), "psf_size", std::to_string(w), [w](optics::PsfSpec& s) { s.psf_size = w; });
  Setting fft{"fft_bilinear", "method", "2x-padded FFT + bilinear (the usual Python code)", base};
  fft.fft_bilinear = true;
  settings.push_back(fft);
  return settings;
}

// Times one setting (forward, forward+backward w.r.t. the height map, upstream
// gradient gw) and measures its error against the reference.
Row measure_setting(const Study& st, const Reference& ref, const Setting& s, const torch::Tensor& gw) {
  log::info("setting " + s.name + " (" + s.knob + " = " + s.value + ") ...");
  const optics::PsfSimulator sim(s.spec);
  auto psf_of = [&](const torch::Tensor& h) -> optics::PsfStack {
    if (!s.fft_bilinear) return sim.compute(h, st.layers);
    optics::PsfStack stack;
    stack.psf = baseline_fft_psf(s.spec, sim.aperture(), h).index_select(1, st.zi);
    return stack;
  };
  auto full_psf = [&](const torch::Tensor& h) -> optics::PsfStack {
    if (!s.fft_bilinear) return sim.compute(h);
    return optics::PsfStack{baseline_fft_psf(s.spec, sim.aperture(), h), torch::Tensor()};
  };
  auto step = [&](bool backward) {
    torch::Tensor h = st.h0.clone().set_requires_grad(backward);
    const torch::Tensor J = st.render_layers(psf_of(h).psf);
    if (backward) (J * gw.to(J.scalar_type())).sum().backward();
  };
  Row r{s};
  r.seconds_fwd = median_seconds([&] { torch::NoGradGuard ng; step(false); }, st.args.repeats);
  r.seconds = median_seconds([&] { step(true); }, st.args.repeats);
  torch::NoGradGuard ng;
  const optics::PsfStack stack = full_psf(st.h0);
  const torch::Tensor p = pad_to(stack.psf.to(torch::kFloat64), st.P);
  const torch::Tensor err = (p - ref.psf).abs().sum({2, 3}) / ref.psf.sum({2, 3});
  r.rel_l1_max = err.max().item<double>();
  const int64_t at = err.argmax().item<int64_t>();
  r.worst_nm = st.base.wavelengths_m[size_t(at / st.Z)] * 1e9, r.worst_depth_m = st.base.depths_m[size_t(at % st.Z)];
  r.rel_l1_mean = err.mean().item<double>();
  r.energy_min = stack.energy_in_window.defined() ? stack.energy_in_window.min().item<double>() : std::nan("");
  r.psnr_db = psnr_db(st.render(p), ref.image);
  check_finite(p, "PSF of setting " + s.name);
  return r;
}

// Leave-out: the same scene with and without skipping unneeded work.
struct LeaveOutCase {
  std::string name, what, left_out;
  double seconds_full = 0, seconds_lean = 0, rel_err = 0;
};

// Median seconds of simulate_sensor, forward+backward (backward = true) or
// forward only without a graph; the clean image and the simulator's record
// of the last run go to image and info when given.
double time_simulation(const Study& st, const optics::PsfSimulator& sim, const torch::Tensor& rad, const torch::Tensor& dep,
                       const optics::LeaveOut& leave, const torch::Tensor& gw, bool backward, torch::Tensor* image,
                       optics::SensorImage* info) {
  auto run = [&] {
    std::unique_ptr<torch::NoGradGuard> ng;
    if (!backward) ng = std::make_unique<torch::NoGradGuard>();
    torch::Tensor h = st.h0.clone().set_requires_grad(backward);
    const auto img = optics::simulate_sensor(sim, st.sensor, h, rad, dep, c10::nullopt, leave);
    if (backward) (img.clean * gw.to(img.clean.scalar_type())).sum().backward();
    if (image) *image = img.clean.detach();
    if (info) *info = img;
  };
  return median_seconds(run, st.args.repeats);
}

// One case: the scene (rad, dep) with nothing left out against `lean`; the
// difference counted over `valid` pixels when given.
LeaveOutCase compare_leave_out(const Study& st, const optics::PsfSimulator& sim, const torch::Tensor& gw,
                               const std::string& name, const std::string& what, const torch::Tensor& rad,
                               const torch::Tensor& dep, optics::LeaveOut lean, const torch::Tensor& valid = torch::Tensor(),
                               bool backward = true) {
  optics::LeaveOut none;
  none.layers = none.bands = false;
  none.band_tol = none.psf_crop_tol = 0.0;
  if (!backward) lean.psf_crop_tol = std::max(lean.psf_crop_tol, 1e-7);
  torch::Tensor a, b;
  optics::SensorImage info;
  LeaveOutCase e{name, what, {}};
  e.seconds_full = time_simulation(st, sim, rad, dep, none, gw, backward, &a, nullptr);
  e.seconds_lean = time_simulation(st, sim, rad, dep, lean, gw, backward, &b, &info);
  e.left_out = std::to_string(st.L - int64_t(info.bands.size())) + "/" + std::to_string(st.L) + " bands, " +
               std::to_string(st.Z - int64_t(info.layers.size())) + "/" + std::to_string(st.Z) + " layers, window " +
               std::to_string(info.psf.size(-1)) + "/" + std::to_string(st.P) + " px";
  torch::Tensor d = (a - b).abs();
  if (valid.defined()) d = d * valid;
  e.rel_err = d.max().item<double>() / std::max(a.abs().max().item<double>(), 1e-30);
  return e;
}

std::vector<LeaveOutCase> leave_out_cases(const Study& st, const torch::Tensor& gw) {
  log::info("leave-out measurements ...");
  const optics::PsfSimulator sim(st.base);
  const int64_t patch = st.args.patch, L = st.L, Z = st.Z;
  const auto& depths = st.base.depths_m;
  std::vector<LeaveOutCase> lo;
  const optics::LeaveOut dflt;
  // (1) a scene on two of the depth layers
  torch::Tensor dep2 = torch::full_like(st.depth, depths.front());
  dep2.narrow(3, 0, patch / 2).fill_(depths.back());
  lo.push_back(compare_leave_out(st, sim, gw, "two_layers",
                                 "scene on 2 of " + std::to_string(Z) +
                                     " depth layers: other layers' PSFs and convolutions skipped",
                                 st.radiance, dep2, dflt));
  // (2) a narrow-band illuminant: bands whose contribution bound is below tol
  const torch::Tensor rad_led = st.lit(optics::illuminant_bands("LED-RGB1", st.base.wavelengths_m, st.base.band_width_m));
  for (double tol : {1e-7, 1e-2}) {
    optics::LeaveOut t = dflt;
    t.band_tol = tol;
    lo.push_back(compare_leave_out(st, sim, gw, "dark_bands_tol_" + format("%.0e", tol),
                                   "LED-RGB1 light: dark bands skipped, contribution bound " + format("%.0e", tol), rad_led,
                                   st.depth, t));
  }
  // (3) a single-band (laser-like) scene: every other band is exactly zero
  torch::Tensor rad_one = torch::zeros_like(st.radiance);
  rad_one.select(1, L / 2).copy_(st.radiance.select(1, L / 2));
  lo.push_back(compare_leave_out(st, sim, gw, "one_band", "monochromatic scene: the other bands' PSFs and FFTs skipped",
                                 rad_one, st.depth, dflt));
  // (4) work restricted to the valid region (a quarter of the patch) and what its PSF reach needs
  torch::Tensor valid = torch::zeros_like(st.depth);
  valid.narrow(2, 0, patch / 2).narrow(3, 0, patch / 2).fill_(1.0);
  optics::LeaveOut masked = dflt;
  masked.valid = valid;
  lo.push_back(compare_leave_out(st, sim, gw, "masked_region",
                                 "only a quarter of the patch valid: rendered on its bounding box plus the PSF reach",
                                 st.radiance, st.depth, masked, valid));
  // (5) forward only (simulation, evaluation): PSF pixels holding < 1e-7 of the light cropped
  lo.push_back(compare_leave_out(st, sim, gw, "psf_crop_forward",
                                 "forward only, no gradient: PSFs cropped to the window holding all but 1e-7 of the light",
                                 st.radiance, st.depth, dflt, torch::Tensor(), false));
  return lo;
}

void write_csvs(const std::string& dir, const std::vector<Row>& rows, const std::vector<LeaveOutCase>& lo) {
  std::string csv = "name,knob,value,seconds,seconds_fwd,psf_rel_l1_max,psf_rel_l1_mean,sensor_psnr_db,energy_in_window_min,worst_nm,worst_depth_m\n";
  for (const auto& r : rows) {
    char buf[512];
    std::snprintf(buf, sizeof buf, "%s,%s,\"%s\",%.5g,%.5g,%.4e,%.4e,%.2f,%.5f,%.0f,%.4g\n", r.s.name.c_str(), r.s.knob.c_str(),
                  r.s.value.c_str(), r.seconds, r.seconds_fwd, r.rel_l1_max, r.rel_l1_mean, r.psnr_db, r.energy_min,
                  r.worst_nm, r.worst_depth_m);
    csv += buf;
  }
  write_text_file(dir + "/error_vs_runtime.csv", csv);
  std::string lcsv = "name,seconds_full,seconds_leave_out,speedup,max_rel_diff,left_out,what\n";
  for (const auto& e : lo) {
    char buf[512];
    std::snprintf(buf, sizeof buf, "%s,%.5g,%.5g,%.3f,%.3e,\"%s\",\"%s\"\n", e.name.c_str(), e.seconds_full, e.seconds_lean,
                  e.seconds_full / e.seconds_lean, e.rel_err, e.left_out.c_str(), e.what.c_str());
    lcsv += buf;
  }
  write_text_file(dir + "/leave_out.csv", lcsv);
}

// accuracy.md's table of settings (Pareto-front rows marked) and its recommendations.
std::string settings_md(const std::vector<Row>& rows, const std::vector<size_t>& front) {
  const Row& def = rows.front();
  std::string md =
      "| setting | knob | value | fwd+bwd [s] | fwd [s] | worst PSF rel. L1 | at (nm, m) | mean PSF rel. L1 | sensor PSNR [dB] | "
      "min energy in window | Pareto |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (size_t i = 0; i < rows.size(); ++i) {
    const auto& r = rows[i];
    const bool pf = std::find(front.begin(), front.end(), i) != front.end();
    char buf[512];
    std::snprintf(buf, sizeof buf, "| %s | %s | %s | %.3f | %.3f | %.2e | %.0f, %.3g | %.2e | %.1f | %.3f | %s |\n",
                  r.s.name.c_str(), r.s.knob.c_str(), r.s.value.c_str(), r.seconds, r.seconds_fwd, r.rel_l1_max,
                  r.worst_nm, r.worst_depth_m, r.rel_l1_mean, r.psnr_db, r.energy_min, pf ? "yes" : "");
    md += buf;
  }
  const Row* cheapest_1pct = nullptr;
  for (size_t i : front)
    if (rows[i].rel_l1_max <= 0.01) { cheapest_1pct = &rows[i]; break; }
  const Row* best_within_2x = nullptr;
  for (const auto& r : rows)
    if (r.seconds <= 2.0 * def.seconds && (!best_within_2x || r.rel_l1_max < best_within_2x->rel_l1_max)) best_within_2x = &r;
  md += "\n## Recommendations\n\n";
  md += std::string("- The default setting's worst PSF error is ") + format("%.2e", def.rel_l1_max) +
        (def.rel_l1_max <= 0.01 ? " (within the 1% target)" : " (**above the 1% target**)") + ", at " +
        format("%.3f", def.seconds) + " s per forward+backward.\n";
  if (cheapest_1pct)
    md += "- Cheapest setting within 1% worst error: `" + cheapest_1pct->s.name + "` (" + cheapest_1pct->s.knob + " = " +
          cheapest_1pct->s.value + ", " + format("%.3f", cheapest_1pct->seconds) + " s, " + format("%.2e", cheapest_1pct->rel_l1_max) + ").\n";
  if (best_within_2x)
    md += "- Most accurate within twice the default's time: `" + best_within_2x->s.name + "` (" + best_within_2x->s.knob +
          " = " + best_within_2x->s.value + ", " + format("%.2e", best_within_2x->rel_l1_max) + ").\n";
  md += "- Settings on the Pareto front (no other setting is both faster and more accurate):";
  for (size_t i : front) md += " `" + rows[i].s.name + "`";
  md += ".\n- The window rows also lose light: their error includes the energy outside the smaller window; "
        "`energy_in_window_min` is the smallest fraction of the aperture's light any (lambda, z) window holds.\n";
  return md;
}

std::string leave_out_md(const std::vector<LeaveOutCase>& lo) {
  std::string md = "\n## Leaving out what a scene does not need\n\n| case | full [s] | leave-out [s] | speed-up | max rel. difference | left out | what |\n|---|---|---|---|---|---|---|\n";
  for (const auto& e : lo) {
    char buf[768];
    std::snprintf(buf, sizeof buf, "| %s | %.3f | %.3f | %.2fx | %.1e | %s | %s |\n", e.name.c_str(), e.seconds_full,
                  e.seconds_lean, e.seconds_full / e.seconds_lean, e.rel_err, e.left_out.c_str(), e.what.c_str());
    md += buf;
  }
  md += "\n(forward+backward of PSF + sensor image unless said otherwise; difference relative to the full image's maximum, "
        "over valid pixels; leave-out keeps the defaults: band bound 1e-7, PSF crop 1e-7 without a gradient.)\n";
  return md;
}

// error_vs_runtime.png and accuracy.md; returns the markdown.
std::string write_report(const std::string& dir, const Study& st, const Reference& ref, const std::vector<Row>& rows,
                         const std::vector<LeaveOutCase>& lo) {
  std::vector<viz::LabelledPoint> pts;
  for (const auto& r : rows) pts.push_back({r.s.name, r.seconds, r.rel_l1_max});
  const int threads = torch::get_num_threads();
  const std::string shape = std::to_string(st.L) + " bands x " + std::to_string(st.Z) + " depths, " +
                            std::to_string(st.P) + " px, " + std::to_string(st.base.doe_samples) + "^2 DOE, ";
  viz::write_pareto_plot(dir + "/error_vs_runtime.png", "PSF error vs time: " + shape + std::to_string(threads) + " threads",
                         "seconds (PSF + sensor image, forward+backward)", "worst PSF relative L1 error", pts, "default", 0.01);
  const auto& a = st.args;
  std::string md = "# Simulator accuracy against run time\n\n";
  md += "Config: " + a.config_path + "; " + std::to_string(st.L) + " of its " + std::to_string(st.bands_all) +
        " bands (band stride " + std::to_string(a.stride) + ", band width " + format("%.3g", st.ocfg.band_width_nm) +
        " nm), " + std::to_string(st.Z) + " depths, " + std::to_string(st.P) + "-pixel window, " +
        std::to_string(st.base.doe_samples) + "^2 DOE samples; test scene " + std::to_string(a.patch) + "x" +
        std::to_string(a.patch) + " px on " + std::to_string(st.layers.size()) + " depth layers; " +
        std::to_string(threads) + " threads.\n\n";
  md += "Reference: float64, exact matrix Fourier transform, 8x8 Gauss nodes per pixel, pupil oversampling " +
        std::to_string(a.ref_os) + ", " + std::to_string(a.ref_sp) + " wavelengths per band (" + format("%.1f", ref.seconds) +
        " s). Check: with the midpoint cell rule instead, the reference moves by " + format("%.1e", ref.rule_check) +
        " (worst, first and last band); errors well above that are not an artefact of the reference's own rule.\n\n";
  md += settings_md(rows, viz::pareto_front(pts));
  md += leave_out_md(lo);
  write_text_file(dir + "/accuracy.md", md);
  return md;
}

Json summary_json(const Study& st, const Reference& ref, const std::vector<Row>& rows, const std::vector<LeaveOutCase>& lo,
                  const std::string& dir) {
  Json j{{"bench", "accuracy"}, {"threads", torch::get_num_threads()}, {"bands", st.L}, {"depths", st.Z},
         {"psf_size", st.P}, {"doe_samples", st.base.doe_samples}, {"reference_seconds", ref.seconds},
         {"reference_rule_check", ref.rule_check}, {"out", dir}};
  Json jr = Json::array();
  for (const auto& r : rows)
    jr.push_back(Json{{"name", r.s.name}, {"knob", r.s.knob}, {"value", r.s.value}, {"seconds", r.seconds},
                      {"seconds_fwd", r.seconds_fwd}, {"psf_rel_l1_max", r.rel_l1_max}, {"psf_rel_l1_mean", r.rel_l1_mean},
                      {"sensor_psnr_db", r.psnr_db}});
  j["settings"] = jr;
  Json jl = Json::array();
  for (const auto& e : lo)
    jl.push_back(Json{{"name", e.name}, {"seconds_full", e.seconds_full}, {"seconds_leave_out", e.seconds_lean},
                      {"max_rel_diff", e.rel_err}});
  j["leave_out"] = jl;
  j["default_psf_rel_l1_max"] = rows.front().rel_l1_max;
  return j;
}

}  // namespace

int bench_accuracy(Config cfg, const AppArgs& args, BenchOutput& out) {
  const StudyArgs a = parse_study_args(args);
  make_dirs(args.out_dir);
  const Study st(cfg, a);
  const Reference ref = compute_reference(st);
  const std::vector<Setting> settings = study_settings(st, cfg);
  const torch::Tensor gw = torch::rand({1, 3, a.patch, a.patch}, torch::kFloat64);  // upstream gradient of the image
  std::vector<Row> rows;
  for (const auto& s : settings) rows.push_back(measure_setting(st, ref, s, gw));
  const std::vector<LeaveOutCase> lo = leave_out_cases(st, gw);
  write_csvs(args.out_dir, rows, lo);
  out.text = write_report(args.out_dir, st, ref, rows, lo);
  out.json = summary_json(st, ref, rows, lo, args.out_dir);
  return 0;
}

}  // namespace hsd::bench
