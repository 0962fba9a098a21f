// hsd_calibrate: point-source captures -> a measured PSF stack and its mismatch
// with the simulator (optics/psf_calibration.h, optics/psf_mismatch.h); or,
// with --make-captures, a synthetic captures folder of a perturbed DOE
// (optics/fabrication_error.h, optics/synthetic_captures.h).
#include <cmath>
#include <cstdio>
#include <optional>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/tensor_io.h"
#include "common/text_format.h"
#include "data/capture_set.h"
#include "optics/doe.h"
#include "optics/fabrication_error.h"
#include "optics/psf.h"
#include "optics/psf_calibration.h"
#include "optics/psf_file.h"
#include "optics/psf_mismatch.h"
#include "optics/spectrum.h"
#include "optics/synthetic_captures.h"
#include "viz/psf_atlas.h"
#include "usage/hsd_calibrate.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

torch::Tensor scalar(double v) { return torch::tensor(v, torch::kFloat64); }

// The PSF stack of `height` with the config's simulator, in a window of `window` px.
torch::Tensor simulate(const Config& cfg, const optics::Material& material, const torch::Tensor& height, int64_t window,
                       const std::string& what) {
  OpticsConfig o = cfg.optics;
  o.psf_size = window;
  const optics::PsfSimulator sim(optics::make_psf_spec(o, material, torch::kCPU));
  torch::NoGradGuard no_grad;
  log::Progress progress(what, int64_t(o.wavelengths_nm.size()));
  return sim.compute(height, {}, [&](int64_t) { progress.step(); }).psf.to(torch::kFloat64);
}

TensorDict psf_entries(const Config& cfg, const optics::Material& material, const torch::Tensor& psf, const torch::Tensor& height) {
  const optics::PsfSpec spec = optics::make_psf_spec(cfg.optics, material, torch::kCPU);
  return optics::psf_file_entries(spec, psf, height,
                                  optics::camera_response(cfg.sensor.camera, spec.wavelengths_m, cfg.optics.band_width_m()));
}

int make_captures(const AppArgs& args, const Config& cfg) {
  const auto material = optics::Material::load(cfg.optics.material);
  const optics::Doe doe = optics::make_doe(cfg.optics, material, cfg.seed, torch::kCPU);
  const auto& S = cfg.calibration.synthetic;
  const int64_t P = cfg.optics.psf_size, F = S.frame_px > 0 ? (S.frame_px | 1) : 4 * P + 1;
  const std::string out = args.out_dir;
  const int64_t L = int64_t(cfg.optics.wavelengths_nm.size()), Z = int64_t(cfg.optics.depths_m.size());
  const int64_t E = S.exposures;
  std::vector<std::string> outputs{out + "/captures.json", out + "/truth_psf.pt", out + "/perturbed_height.pt"};
  auto frame_name = [](int64_t l, int64_t z, int64_t e) {
    return "psf_b" + std::to_string(l) + "_z" + std::to_string(z) + "_e" + std::to_string(e) + ".png";
  };
  auto dark_name = [](int64_t e) { return "dark_e" + std::to_string(e) + ".png"; };
  for (int64_t e = 0; e < E; ++e) {
    outputs.push_back(out + "/" + dark_name(e));
    for (int64_t l = 0; l < L; ++l)
      for (int64_t z = 0; z < Z; ++z) outputs.push_back(out + "/" + frame_name(l, z, e));
  }
  setup_threads(cfg.threads);
  make_dirs(out);
  check_output_paths(outputs);
  const torch::Tensor ideal = doe.height().detach().to(torch::kFloat64);
  const torch::Tensor height = optics::apply_fabrication_error(
      ideal, cfg.fabrication.error, {cfg.optics.doe_pitch_m, 1, doe.max_height_m(), cfg.fabrication.levels}, cfg.seed + 17);
  const double rms = (height - ideal).pow(2).mean().sqrt().item<double>();
  log::info("DOE " + choice_word(cfg.optics.doe.init, cfg.optics.doe.init_path) + " perturbed by fabrication.error: RMS height change " + c10::str(rms * 1e9) + " nm");
  const torch::Tensor frames_light = simulate(cfg, material, height, F, "PSFs on the frame");
  const torch::Tensor truth = simulate(cfg, material, height, P, "PSFs in the window");
  const optics::SyntheticCaptures cap = optics::synthesize_captures(frames_light, S, uint64_t(S.seed) * 1000003ULL + 29);
  Json files = Json::array();
  for (int64_t l = 0; l < L; ++l) {
    Json row = Json::array();
    for (int64_t z = 0; z < Z; ++z) {
      Json exposures = Json::array();
      for (int64_t e = 0; e < E; ++e) {
        data::write_png16(out + "/" + frame_name(l, z, e), cap.frames[l][z][e]);
        exposures.push_back(frame_name(l, z, e));
      }
      row.push_back(exposures);
    }
    files.push_back(row);
  }
  Json darks = Json::array();
  for (int64_t e = 0; e < E; ++e) {
    data::write_png16(out + "/" + dark_name(e), cap.dark[e]);
    darks.push_back(dark_name(e));
  }
  save_tensor_dict(out + "/perturbed_height.pt", {{"height_map_m", height.to(torch::kFloat32)}, {"doe_pitch_m", scalar(cfg.optics.doe_pitch_m)}});
  optics::write_psf_file(out + "/truth_psf.pt", psf_entries(cfg, material, truth, height), "simulated");
  Json j;
  j["_note"] = "Synthetic captures made by hsd_calibrate --make-captures: the configured DOE perturbed by fabrication.error, "
               "point sources on the optical axis at axis_px, 16-bit counts with Poisson light and background, dark level, "
               "read noise and hot pixels (calibration.synthetic); each slice's exposures are averaged.";
  j["wavelengths_nm"] = cfg.optics.wavelengths_nm;
  j["depths_m"] = cfg.optics.depths_m;
  j["pixel_pitch_m"] = cfg.optics.pixel_pitch_m;
  j["files"] = files;
  j["dark"] = darks;
  j["axis_px"] = {cap.axis_px.first, cap.axis_px.second};
  write_text_file(out + "/captures.json", j.dump(2) + "\n");
  write_resolved_config(cfg, out);
  log::info("wrote " + std::to_string(L * Z) + " x " + std::to_string(E) + " captures of " + std::to_string(F) + "x" +
            std::to_string(F) + " px, " + std::to_string(E) + " dark frames, captures.json, truth_psf.pt and perturbed_height.pt to " + out);
  return 0;
}

void check_matches(const data::CaptureSet& c, const Config& cfg, const std::string& file) {
  auto differ = [](const std::vector<double>& a, const std::vector<double>& b, double tol_rel) {
    if (a.size() != b.size()) return true;
    for (size_t i = 0; i < a.size(); ++i)
      if (!(std::abs(a[i] - b[i]) <= tol_rel * std::abs(b[i]))) return true;
    return false;
  };
  if (differ(c.wavelengths_nm, cfg.optics.wavelengths_nm, 1e-5))
    input_error(file, "key wavelengths_nm: " + Json(c.wavelengths_nm).dump() + " differs from the config's optics.wavelengths_nm " +
                          Json(cfg.optics.wavelengths_nm).dump());
  if (differ(c.depths_m, cfg.optics.depths_m, 1e-6))
    input_error(file, "key depths_m: " + Json(c.depths_m).dump() + " differs from the config's optics.depths_m " +
                          Json(cfg.optics.depths_m).dump());
  if (differ({c.pixel_pitch_m}, {cfg.optics.pixel_pitch_m}, 1e-6))
    input_error(file, "key pixel_pitch_m: " + c10::str(c.pixel_pitch_m) + " differs from the config's optics.pixel_pitch_m " +
                          c10::str(cfg.optics.pixel_pitch_m));
}

// Measured | simulated atlases side by side under a title strip.
void write_mismatch_png(const std::string& path, const torch::Tensor& measured, const torch::Tensor& simulated,
                        const optics::PsfSpec& spec) {
  auto to_mat = [](const torch::Tensor& t) {
    const torch::Tensor c = t.contiguous();
    return cv::Mat(int(c.size(0)), int(c.size(1)), CV_8UC3, c.data_ptr<uint8_t>()).clone();
  };
  const cv::Mat a = to_mat(viz::render_psf_atlas(measured, spec.wavelengths_m, spec.depths_m));
  const cv::Mat b = to_mat(viz::render_psf_atlas(simulated, spec.wavelengths_m, spec.depths_m));
  const int gap = 16, title = 30;
  cv::Mat img(std::max(a.rows, b.rows) + title, a.cols + gap + b.cols, CV_8UC3, cv::Scalar(255, 255, 255));
  a.copyTo(img(cv::Rect(0, title, a.cols, a.rows)));
  b.copyTo(img(cv::Rect(a.cols + gap, title, b.cols, b.rows)));
  cv::putText(img, "measured (calibrated captures)", {8, 21}, cv::FONT_HERSHEY_SIMPLEX, 0.6, {0, 0, 0}, 1, cv::LINE_AA);
  cv::putText(img, "simulated (configured DOE)", {a.cols + gap + 8, 21}, cv::FONT_HERSHEY_SIMPLEX, 0.6, {0, 0, 0}, 1, cv::LINE_AA);
  std::vector<uchar> buf;
  cv::imencode(".png", img, buf);
  write_binary_file(path, std::vector<char>(buf.begin(), buf.end()));
}

// Every capture's calibration, [L, Z] per quantity (centroid [L, Z, 2] (row,
// col) px); every capture is read and checked before anything is printed, so
// a bad one is exit 2 with one line.
struct CalibratedSlices {
  torch::Tensor psf;  // [L, Z, P, P] float64
  torch::Tensor background, sigma, snr, energy, centroid, hot;
};

CalibratedSlices calibrate_slices(const data::CaptureSet& caps, const torch::Tensor& dark, int64_t P,
                                  const CalibrationConfig& K, const std::optional<std::pair<double, double>>& axis,
                                  bool ring_background) {
  const int64_t L = int64_t(caps.wavelengths_nm.size()), Z = int64_t(caps.depths_m.size());
  const auto f64 = torch::kFloat64;
  CalibratedSlices s{torch::zeros({L, Z, P, P}, f64), torch::zeros({L, Z}, f64), torch::zeros({L, Z}, f64),
                     torch::zeros({L, Z}, f64),       torch::zeros({L, Z}, f64), torch::zeros({L, Z, 2}, f64),
                     torch::zeros({L, Z}, torch::kInt64)};
  for (int64_t l = 0; l < L; ++l)
    for (int64_t z = 0; z < Z; ++z) {
      const auto& files = caps.files[size_t(l)][size_t(z)];
      const data::CaptureFrame fr = data::read_capture_frames(files);
      const double sat = caps.saturation >= 0 ? caps.saturation : fr.saturation;
      const optics::CapturedPsf c = optics::calibrate_capture(fr.counts, dark, P, K, sat, axis, files.front(), ring_background);
      s.psf[l][z].copy_(c.psf);
      s.background[l][z] = c.background, s.sigma[l][z] = c.noise_sigma, s.snr[l][z] = c.snr;
      s.energy[l][z] = c.energy_in_window;
      s.centroid[l][z][0] = c.centroid_px.first, s.centroid[l][z][1] = c.centroid_px.second;
      s.hot[l][z] = c.hot_pixels;
    }
  return s;
}

// [L, Z] or [L, Z, 2] -> nested JSON arrays.
Json nested_json(const torch::Tensor& t) {
  Json j = Json::array();
  const torch::Tensor c = t.to(torch::kFloat64).contiguous();
  for (int64_t l = 0; l < c.size(0); ++l) {
    Json row = Json::array();
    for (int64_t z = 0; z < c.size(1); ++z) {
      if (c.dim() == 2) row.push_back(c[l][z].item<double>());
      else row.push_back({c[l][z][0].item<double>(), c[l][z][1].item<double>()});
    }
    j.push_back(row);
  }
  return j;
}

// mismatch.json without the reference's part.
Json mismatch_json(const optics::PsfMismatch& mm, const CalibratedSlices& s, const Config& cfg, bool axis) {
  Json m;
  m["rel_l1"] = nested_json(mm.rel_l1);
  m["rel_l1_mean"] = mm.rel_l1.mean().item<double>();
  m["rel_l1_max"] = mm.rel_l1.max().item<double>();
  m["centroid_shift_px"] = nested_json(mm.centroid_shift_px);
  m["tail_energy_measured"] = nested_json(mm.tail_measured);
  m["tail_energy_simulated"] = nested_json(mm.tail_simulated);
  m["core_radius_px"] = nested_json(mm.core_radius_px);
  m["snr"] = nested_json(s.snr);
  m["energy_in_window"] = nested_json(s.energy);
  m["energy_in_window_mean"] = s.energy.mean().item<double>();
  m["background_counts"] = nested_json(s.background);
  m["hot_pixels"] = nested_json(s.hot);
  m["wavelengths_nm"] = cfg.optics.wavelengths_nm;
  m["depths_m"] = cfg.optics.depths_m;
  m["registration"] = axis ? "axis" : "centroid";
  m["_note"] = "rel_l1: sum |measured - simulated| / sum simulated per (band, depth); centroid_shift_px: centroid of the measured "
               "window minus the simulated one's, (row, col); tail_energy: light outside the radius holding 80 % of the "
               "simulated PSF (0.2 for the simulated one); snr: peak over the noise sigma of each capture; energy_in_window: the "
               "dark-subtracted light in the window over the frame's.";
  return m;
}

// The log's table: per band (rows) and depth (columns) relative L1 | tail energy measured/simulated | SNR.
std::string mismatch_table(const optics::PsfMismatch& mm, const torch::Tensor& snr, const std::vector<double>& wavelengths_nm) {
  std::string table = "measured against simulated, per band (rows) and depth (columns): relative L1 | tail energy measured/simulated | SNR";
  char buf[96];
  for (int64_t l = 0; l < mm.rel_l1.size(0); ++l) {
    std::snprintf(buf, sizeof buf, "\n  %4.0f nm ", wavelengths_nm[size_t(l)]);
    table += buf;
    for (int64_t z = 0; z < mm.rel_l1.size(1); ++z) {
      std::snprintf(buf, sizeof buf, "  %.3f|%.2f/%.2f|%.0f", mm.rel_l1[l][z].item<double>(), mm.tail_measured[l][z].item<double>(),
                    mm.tail_simulated[l][z].item<double>(), snr[l][z].item<double>());
      table += buf;
    }
  }
  return table;
}

int calibrate(const AppArgs& args, const Config& cfg) {
  const std::string dir = args.option("--captures", "");
  const data::CaptureSet caps = data::read_capture_set(dir);
  const std::string json = dir + "/captures.json";
  check_matches(caps, cfg, json);
  const auto& K = cfg.calibration;
  std::optional<std::pair<double, double>> axis;
  if (K.registration == Registration::axis && !caps.axis_px)
    input_error(json, "calibration.registration = \"axis\" needs the key axis_px (the optical axis in the frames)");
  if (K.registration != Registration::centroid && caps.axis_px) axis = caps.axis_px;
  const auto material = optics::Material::load(cfg.optics.material);
  const optics::Doe doe = optics::make_doe(cfg.optics, material, cfg.seed, torch::kCPU);  // reads DOE files: may fail
  const int64_t P = cfg.optics.psf_size;
  make_dirs(args.out_dir);
  check_output_paths({args.out_dir + "/psf.pt", args.out_dir + "/mismatch.json", args.out_dir + "/mismatch.png",
                      args.out_dir + "/config.json"});
  torch::Tensor dark, reference;
  if (!caps.dark.empty()) dark = data::read_capture_frames(caps.dark).counts;
  const std::string ref = args.option("--reference", "");
  if (args.has("--reference")) reference = optics::psf_for_config(optics::read_psf_file(ref), cfg.optics, ref, "--reference", torch::kCPU);
  if (K.background == CaptureBackground::dark && caps.dark.empty())
    input_error(json, "calibration.background = \"dark\" needs the key dark (frames taken with the source off)");
  const bool ring_background = K.background == CaptureBackground::ring || (K.background == CaptureBackground::automatic && caps.dark.empty());
  setup_threads(cfg.threads, /*print=*/false);
  const CalibratedSlices s = calibrate_slices(caps, dark, P, K, axis, ring_background);
  setup_threads(cfg.threads);  // prints the thread count
  log::info(std::string("calibrated ") + std::to_string(s.psf.size(0) * s.psf.size(1)) + " slices; background: " +
            (ring_background ? "the median of each frame's outer ring" : "the dark frames (source off) hold all of it") +
            "; registration: " +
            (axis ? "to the optical axis at (" + c10::str(axis->first) + ", " + c10::str(axis->second) + ") px (captures.json axis_px)"
                  : std::string("each slice centred on its centroid")));
  const torch::Tensor sim = simulate(cfg, material, doe.height().detach(), P, "simulated PSFs");
  const optics::PsfMismatch mm = optics::compare_psfs(s.psf, sim);
  TensorDict entries = psf_entries(cfg, material, s.psf, torch::Tensor());  // the captured DOE's height is not known
  entries["energy_in_window"] = s.energy.to(torch::kFloat32);
  entries["background_counts"] = s.background;
  entries["noise_sigma_counts"] = s.sigma;
  entries["snr"] = s.snr;
  entries["centroid_px"] = s.centroid;
  entries["hot_pixels"] = s.hot;
  Json m = mismatch_json(mm, s, cfg, bool(axis));
  if (reference.defined()) {  // e.g. the synthetic captures' truth_psf.pt: how close the calibration came
    const torch::Tensor d = optics::compare_psfs(s.psf, reference).rel_l1;
    m["reference"] = ref;
    m["reference_rel_l1"] = nested_json(d);
    m["reference_rel_l1_mean"] = d.mean().item<double>();
    m["reference_rel_l1_max"] = d.max().item<double>();
    log::info(format("against the reference %s: relative L1 mean %.4f, max %.4f", ref.c_str(), d.mean().item<double>(),
                     d.max().item<double>()));
  }
  optics::write_psf_file(args.out_dir + "/psf.pt", entries, "measured");
  write_text_file(args.out_dir + "/mismatch.json", m.dump(2) + "\n");
  write_mismatch_png(args.out_dir + "/mismatch.png", s.psf, sim, optics::make_psf_spec(cfg.optics, material, torch::kCPU));
  write_resolved_config(cfg, args.out_dir);
  log::info(mismatch_table(mm, s.snr, cfg.optics.wavelengths_nm));
  log::info(format("relative L1 mean %.4f, max %.4f; light in the window %.1f %% of the frame's (mean); %lld hot pixels replaced",
                   m["rel_l1_mean"].get<double>(), m["rel_l1_max"].get<double>(), 100.0 * s.energy.mean().item<double>(),
                   (long long)s.hot.sum().item<int64_t>()));
  log::info("wrote " + args.out_dir + "/psf.pt (use it: --set optics.psf_source=\\\"file:" + args.out_dir +
            "/psf.pt\\\"), mismatch.json, mismatch.png, config.json");
  return 0;
}

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  const bool make = args.has("--make-captures");
  if (make == args.has("--captures"))
    input_error("--captures/--make-captures", "give exactly one: a captures folder to calibrate, or --make-captures");
  return make ? make_captures(args, cfg) : calibrate(args, cfg);
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_calibrate", kUsage, {"--captures", "--reference"}, {"--make-captures"}, true, true};
  return run_app(spec, argc, argv, run);
}
