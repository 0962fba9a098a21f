// From simulation to a real camera: PSF files as the imaging PSFs
// (optics/psf_file.h, psf_source.h), fabrication errors (fabrication_error.h),
// calibration of point-source captures (psf_calibration.h, synthetic_captures.h),
// the mismatch report (psf_mismatch.h), and hsd_calibrate / train.init_checkpoint
// / hsd_eval --camera-psf as a user runs them.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <torch/torch.h>

#include "common/config.h"
#include "common/error.h"
#include "common/tensor_io.h"
#include "helpers.h"
#include "optics/doe.h"
#include "optics/fabrication_error.h"
#include "optics/psf.h"
#include "optics/psf_calibration.h"
#include "optics/psf_file.h"
#include "optics/psf_mismatch.h"
#include "optics/psf_source.h"
#include "optics/sensor.h"
#include "optics/synthetic_captures.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

// A smooth, asymmetric PSF [P, P] summing to 1: two Gaussians.
torch::Tensor test_psf(int64_t P) {
  const torch::Tensor c = torch::arange(P, torch::kFloat64) - double(P / 2);
  const torch::Tensor y = c.view({-1, 1}), x = c.view({1, -1});
  torch::Tensor p = torch::exp(-(y.pow(2) + x.pow(2)) / (2 * 1.6 * 1.6)) +
                    0.3 * torch::exp(-((y - 2).pow(2) + (x + 1).pow(2)) / (2 * 3.0 * 3.0));
  return p / p.sum();
}

// The PSF placed on a frame [F, F] with its window centre at (F/2 + dy, F/2 + dx).
torch::Tensor on_frame(const torch::Tensor& psf, int64_t F, double dy, double dx) {
  const int64_t P = psf.size(0);
  torch::Tensor f = torch::zeros({F, F}, torch::kFloat64);
  f.narrow(0, F / 2 - P / 2, P).narrow(1, F / 2 - P / 2, P).copy_(psf);
  return optics::fourier_shift(f, dy, dx);
}

double rel_l1(const torch::Tensor& a, const torch::Tensor& b) {
  return ((a - b).abs().sum() / b.abs().sum()).item<double>();
}

}  // namespace

TEST_CASE("fourier_shift moves a blob by sub-pixel amounts and back", "[calibration]") {
  const torch::Tensor p = test_psf(31);
  torch::Tensor f = torch::zeros({61, 61}, torch::kFloat64);
  f.narrow(0, 15, 31).narrow(1, 15, 31).copy_(p);
  const auto c0 = optics::image_centroid(f);
  const torch::Tensor s = optics::fourier_shift(f, 0.3, -0.7);
  const auto c1 = optics::image_centroid(s);
  CHECK(c1.first - c0.first == Approx(0.3).margin(1e-6));
  CHECK(c1.second - c0.second == Approx(-0.7).margin(1e-6));
  CHECK(s.sum().item<double>() == Approx(1.0).margin(1e-12));
  // Back: exact but for the Nyquist terms, where the blob's spectrum is exp(-2π²σ²/4) ≈ 3e-6.
  CHECK(rel_l1(optics::fourier_shift(s, -0.3, 0.7), f) < 1e-5);
  // Whole pixels: an exact move.
  CHECK(rel_l1(optics::fourier_shift(f, 2.0, -3.0), torch::roll(f, {2, -3}, {0, 1})) < 1e-10);
}

TEST_CASE("calibration finds shift, background and hot pixels of a noiseless capture exactly", "[calibration]") {
  const int64_t P = 31, F = 101;
  const torch::Tensor psf = test_psf(P);
  const double dy = 3.25, dx = -4.6;
  const torch::Tensor light = on_frame(psf, F, dy, dx) * (30000.0 / psf.max().item<double>());
  torch::Tensor dark = torch::full({F, F}, 100.0, torch::kFloat64);
  torch::Tensor frame = light + 150.0 + dark;
  // Ten hot pixels, away from the PSF, in the capture only.
  const std::vector<std::pair<int64_t, int64_t>> hot{{3, 5}, {7, 90}, {95, 95}, {20, 10}, {80, 12},
                                                     {60, 85}, {10, 50}, {90, 40}, {5, 5}, {96, 70}};
  for (auto [r, c] : hot) frame[r][c] += 20000.0;
  CalibrationConfig opt;
  const double axis_r = double(F / 2) + dy, axis_c = double(F / 2) + dx;
  const optics::CapturedPsf a = optics::calibrate_capture(frame, dark, P, opt, 65535.0, std::make_pair(axis_r, axis_c), "t.png");
  CHECK(a.hot_pixels == int64_t(hot.size()));
  CHECK(a.background == Approx(150.0).margin(0.05));
  // Registered to the axis: the window is the PSF itself.
  CHECK(rel_l1(a.psf, psf) < 1e-3);
  const auto pc = optics::image_centroid(psf);
  CHECK(a.centroid_px.first == Approx(axis_r + pc.first - double(P / 2)).margin(5e-3));
  CHECK(a.centroid_px.second == Approx(axis_c + pc.second - double(P / 2)).margin(5e-3));
  // Registered to the centroid: the PSF moved so its centroid is the window's centre.
  const optics::CapturedPsf b = optics::calibrate_capture(frame, dark, P, opt, 65535.0, std::nullopt, "t.png");
  const auto bc = optics::image_centroid(b.psf);
  CHECK(bc.first == Approx(double(P / 2)).margin(2e-3));
  CHECK(bc.second == Approx(double(P / 2)).margin(2e-3));
  torch::Tensor centred = torch::zeros({F, F}, torch::kFloat64);
  centred.narrow(0, F / 2 - P / 2, P).narrow(1, F / 2 - P / 2, P).copy_(psf);
  centred = optics::fourier_shift(centred, double(P / 2) - pc.first, double(P / 2) - pc.second);
  CHECK(rel_l1(b.psf, centred.narrow(0, F / 2 - P / 2, P).narrow(1, F / 2 - P / 2, P)) < 2e-3);
}

TEST_CASE("calibration of noisy synthetic captures recovers the PSF to within the noise", "[calibration]") {
  const int64_t P = 31, F = 91;
  const torch::Tensor psf = test_psf(P);
  torch::Tensor frames = on_frame(psf, F, 0.0, 0.0).view({1, 1, F, F});
  SyntheticCaptureConfig sc;
  sc.hot_pixels = 15;
  sc.exposures = 1;
  sc.axis_offset_px = {0.41, -0.27};
  const optics::SyntheticCaptures cap = optics::synthesize_captures(frames, sc, 5);
  CalibrationConfig opt;
  const optics::CapturedPsf c = optics::calibrate_capture(cap.frames[0][0][0], cap.dark[0], P, opt, 65535.0, cap.axis_px, "t.png");
  // The noise's expected L1 over the window, relative to the light in it: E|n| = sqrt(2/π) σ per pixel,
  // σ² = light + 2 (stray light + read²): the dark frame (source off) holds the stray light too.
  const double k = sc.peak_counts / psf.max().item<double>();
  const torch::Tensor var = psf * k + 2 * (sc.background_counts + sc.read_noise_counts * sc.read_noise_counts);
  const double expected = (std::sqrt(2.0 / M_PI) * var.sqrt().sum() / (psf.sum() * k)).item<double>();
  INFO("rel L1 " << rel_l1(c.psf, psf) << ", expected from the noise " << expected << ", hot " << c.hot_pixels);
  CHECK(rel_l1(c.psf, psf) < 1.5 * expected);
  CHECK(rel_l1(c.psf, psf) > 0.5 * expected);  // the noise is there: the bound is not vacuous
  CHECK(c.background == Approx(0.0).margin(3.0));  // what is left after the dark frame: nothing
  CHECK(c.snr > 100);
}

TEST_CASE("calibration refuses saturated, empty, too small and edge captures", "[calibration][bad_input]") {
  const int64_t P = 15, F = 61;
  const torch::Tensor psf = test_psf(P);
  CalibrationConfig opt;
  torch::Tensor sat = on_frame(psf, F, 0, 0) * (80000.0 / psf.max().item<double>()) + 100;
  sat = sat.clamp_max(65535.0);
  CHECK_THROWS_AS(optics::calibrate_capture(sat, {}, P, opt, 65535.0, std::nullopt, "s.png"), InputError);
  auto gen = at::detail::createCPUGenerator(3);
  const torch::Tensor noise = 100 + 3 * at::normal(0.0, 1.0, {F, F}, gen, torch::TensorOptions().dtype(torch::kFloat64));
  try {
    optics::calibrate_capture(noise, {}, P, opt, 65535.0, std::nullopt, "n.png");
    FAIL("no error for a frame without a point source");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("n.png"));
  }
  CHECK_THROWS_AS(optics::calibrate_capture(torch::ones({10, 10}), {}, P, opt, 0, std::nullopt, "small.png"), InputError);
  const torch::Tensor edge = on_frame(psf, F, 0, 27) * 1000 + 10;
  CHECK_THROWS_AS(optics::calibrate_capture(edge, {}, P, opt, 0, std::nullopt, "edge.png"), InputError);
  CHECK_THROWS_AS(optics::calibrate_capture(edge, torch::zeros({F, F + 1}), P, opt, 0, std::nullopt, "dark.png"), InputError);
}

TEST_CASE("fabrication errors: identity, exact scale, RMS and correlation of roughness, blur keeps constants", "[calibration]") {
  auto gen = at::detail::createCPUGenerator(1);
  const torch::Tensor h = 1e-6 * (1.0 + at::rand({64, 64}, gen, torch::TensorOptions().dtype(torch::kFloat64)));
  FabricationErrorConfig e;
  CHECK(torch::equal(optics::apply_fabrication_error(h, e, {8e-6}, 0), h));
  e.height_scale_error = 0.05;
  CHECK(torch::allclose(optics::apply_fabrication_error(h, e, {8e-6}, 0), 1.05 * h, 0, 1e-18));
  e = {};
  e.roughness_rms_m = 20e-9;
  const torch::Tensor d = optics::apply_fabrication_error(h, e, {8e-6}, 0) - h;
  CHECK(d.pow(2).mean().sqrt().item<double>() == Approx(20e-9).epsilon(1e-9));
  auto neighbour_corr = [](const torch::Tensor& r) {
    const torch::Tensor a = r.narrow(1, 0, r.size(1) - 1), b = r.narrow(1, 1, r.size(1) - 1);
    return ((a * b).mean() / r.pow(2).mean()).item<double>();
  };
  CHECK(std::abs(neighbour_corr(d)) < 0.1);  // white
  e.roughness_correlation_m = 24e-6;         // 3 samples
  CHECK(neighbour_corr(optics::apply_fabrication_error(h, e, {8e-6}, 0) - h) > 0.8);
  const torch::Tensor flat = torch::full({32, 32}, 5e-7, torch::kFloat64);
  CHECK(torch::allclose(optics::gaussian_blur_2d(flat, 2.5), flat, 1e-12, 0));
  e = {};
  e.edge_blur_m = 16e-6;
  const torch::Tensor blurred = optics::apply_fabrication_error(h, e, {8e-6}, 0);
  CHECK(blurred.std().item<double>() < 0.5 * h.std().item<double>());
  CHECK(blurred.mean().item<double>() == Approx(h.mean().item<double>()).epsilon(0.01));
}

TEST_CASE("PSF mismatch: zero for the same stack, the shift of a shifted one, a long tail shows", "[calibration]") {
  const int64_t P = 31;
  const torch::Tensor s = test_psf(P).view({1, 1, P, P});
  optics::PsfMismatch m = optics::compare_psfs(s, s);
  CHECK(m.rel_l1.max().item<double>() == 0.0);
  CHECK(m.tail_simulated[0][0].item<double>() == Approx(0.2).margin(0.03));
  CHECK(m.tail_measured[0][0].item<double>() == m.tail_simulated[0][0].item<double>());
  torch::Tensor f = torch::zeros({P + 20, P + 20}, torch::kFloat64);
  f.narrow(0, 10, P).narrow(1, 10, P).copy_(s[0][0]);
  const torch::Tensor shifted = optics::fourier_shift(f, 0.5, -1.25).narrow(0, 10, P).narrow(1, 10, P).view({1, 1, P, P});
  m = optics::compare_psfs(shifted, s);
  CHECK(m.centroid_shift_px[0][0][0].item<double>() == Approx(0.5).margin(0.02));
  CHECK(m.centroid_shift_px[0][0][1].item<double>() == Approx(-1.25).margin(0.02));
  const torch::Tensor tail = 0.8 * s + 0.2 / double(P * P);  // a fifth of the light spread flat
  m = optics::compare_psfs(tail, s);
  CHECK(m.tail_measured[0][0].item<double>() > m.tail_simulated[0][0].item<double>() + 0.1);
  CHECK(m.rel_l1[0][0].item<double>() > 0.2);
}

TEST_CASE("psf_source = file: the simulator's own stack images exactly as the simulator", "[calibration][sensor]") {
  Config cfg = load_config(test::source_path("configs/tiny.json"), {});
  const auto material = optics::Material::load(cfg.optics.material);
  const optics::PsfSimulator sim(optics::make_psf_spec(cfg.optics, material, torch::kCPU));
  const torch::Tensor h = optics::make_doe(cfg.optics, material, 0, torch::kCPU).height().detach();
  const torch::Tensor stack = sim.compute(h).psf;
  const fs::path dir = fs::temp_directory_path() / "hsd_test_psf_file";
  fs::create_directories(dir);
  const std::string path = (dir / "psf.pt").string();
  optics::write_psf_file(path,
                         {{"psf", stack.to(torch::kFloat32)},
                          {"wavelengths_m", torch::tensor(cfg.optics.wavelengths_m(), torch::kFloat64)},
                          {"depths_m", torch::tensor(cfg.optics.depths_m, torch::kFloat64)},
                          {"pixel_pitch_m", torch::tensor(cfg.optics.pixel_pitch_m, torch::kFloat64)}},
                         "simulated");
  CHECK(optics::read_psf_file(path).source == "simulated");
  Config file_cfg = cfg;
  file_cfg.optics.psf_source = PsfSource::file;
  file_cfg.optics.psf_path = path;
  const optics::PsfProvider provider = optics::psf_source_provider(file_cfg.optics, material, torch::kCPU);
  REQUIRE(provider);
  const optics::SensorModel sensor = optics::make_sensor_model(cfg.sensor, sim.spec(), cfg.optics.band_width_m());
  auto gen = at::detail::createCPUGenerator(0);
  const torch::Tensor radiance = at::rand({1, 3, 40, 40}, gen, torch::TensorOptions().dtype(sim.spec().real_dtype));
  torch::Tensor depth = torch::full({1, 1, 40, 40}, 0.5, radiance.options());
  depth.narrow(3, 20, 20).fill_(1.5);
  torch::NoGradGuard no_grad;
  const torch::Tensor a = optics::simulate_sensor(sim, sensor, h, radiance, depth).image;
  const torch::Tensor b = optics::simulate_sensor(sim, sensor, h, radiance, depth, {}, optics::LeaveOut(), provider).image;
  CHECK((a - b).abs().max().item<double>() < 1e-6 * a.abs().max().item<double>());
  // A stack of other wavelengths or depths is refused, naming the key.
  Config other = file_cfg;
  other.optics.depths_m = {0.5, 2.0};
  try {
    optics::psf_source_provider(other.optics, material, torch::kCPU);
    FAIL("no error for mismatched depths");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("optics.psf_source") && Catch::Contains("depths"));
  }
  // A negative slice is not a PSF.
  TensorDict d = load_tensor_dict(path);
  d["psf"] = d["psf"].clone();
  d["psf"][0][0] = -d["psf"][0][0];
  save_tensor_dict((dir / "neg.pt").string(), d);
  CHECK_THROWS_AS(optics::read_psf_file((dir / "neg.pt").string()), InputError);
}

TEST_CASE("hsd_calibrate: synthetic captures of a perturbed DOE calibrate back to its PSFs within the noise", "[calibration][app]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_calibrate";
  fs::remove_all(base);
  const std::string sets = " --set fabrication.error.height_scale_error=0.15 --set fabrication.error.roughness_rms_m=3e-8";
  const test::Run make =
      test::run("hsd_calibrate --config configs/tiny.json --make-captures" + sets + " --out " + (base / "caps").string());
  INFO(make.err);
  REQUIRE(make.code == 0);
  const test::Run cal = test::run("hsd_calibrate --config configs/tiny.json --captures " + (base / "caps").string() +
                                  " --out " + (base / "cal").string());
  INFO(cal.err);
  REQUIRE(cal.code == 0);
  const optics::PsfFile measured = optics::read_psf_file((base / "cal/psf.pt").string());
  const optics::PsfFile truth = optics::read_psf_file((base / "caps/truth_psf.pt").string());
  CHECK(measured.source == "measured");
  const torch::Tensor d = (measured.psf - truth.psf).abs().sum({2, 3}).to(torch::kFloat64);
  INFO("rel L1 per slice " << d);
  CHECK(d.max().item<double>() < 0.05);
  for (const char* f : {"mismatch.json", "mismatch.png", "config.json"}) CHECK(fs::exists(base / "cal" / f));
  // The perturbed DOE differs from the configured one more than the calibration from the truth.
  std::ifstream mj(base / "cal/mismatch.json");
  const Json m = Json::parse(mj);
  CHECK(m["rel_l1_mean"].get<double>() > 2 * d.mean().item<double>());
  CHECK(m["rel_l1"].size() == 3);
  CHECK(m["centroid_shift_px"][0][0].size() == 2);
}

TEST_CASE("train.init_checkpoint and a PSF file: fine-tuning starts exactly where the first run ended", "[calibration][app][train]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_finetune";
  fs::remove_all(base);
  const std::string sets = test::tiny_run_sets(base / "data") + " --set train.steps=3 --set train.freeze_doe=true";
  const std::string cfg = "--config configs/tiny.json" + sets;
  REQUIRE(test::run("hsd_train " + cfg + " --out " + (base / "a").string()).code == 0);
  REQUIRE(test::run("hsd_psf " + cfg + " --out " + (base / "psf").string()).code == 0);
  const std::string file = (base / "psf/psf.pt").string(), ckpt = (base / "a/checkpoints/last.pt").string();
  const test::Run b = test::run("hsd_train " + cfg + " --set optics.psf_source=file:" + file +
                                " --set train.init_checkpoint=" + ckpt + " --out " + (base / "b").string());
  INFO(b.err);
  REQUIRE(b.code == 0);
  auto val_losses = [](const fs::path& csv) {  // the rows with a validation loss
    std::vector<double> v;
    for (double x : test::csv_column(csv, "val_loss"))
      if (!std::isnan(x)) v.push_back(x);
    return v;
  };
  const std::vector<double> va = val_losses(base / "a/metrics.csv"), vb = val_losses(base / "b/metrics.csv");
  REQUIRE(va.size() >= 2);
  REQUIRE(!vb.empty());
  // The second run's step 0 is the first run's last network, imaged through the same PSFs (read from the file).
  CHECK(vb.front() == Approx(va.back()).epsilon(1e-3));
  CHECK(std::abs(vb.front() - va.front()) > 1e-6);  // and not the untrained network's
  // A camera that differs from the model: hsd_eval --camera-psf images through another stack.
  const test::Run caps = test::run("hsd_calibrate " + cfg + " --set fabrication.error.height_scale_error=0.1 --make-captures --out " +
                                   (base / "caps").string());
  REQUIRE(caps.code == 0);
  const test::Run e1 = test::run("hsd_eval " + cfg + " --checkpoint " + ckpt + " --out " + (base / "e1").string());
  const test::Run e2 = test::run("hsd_eval " + cfg + " --checkpoint " + ckpt + " --camera-psf " +
                                 (base / "caps/truth_psf.pt").string() + " --out " + (base / "e2").string());
  INFO(e1.err << e2.err);
  REQUIRE(e1.code == 0);
  REQUIRE(e2.code == 0);
  std::ifstream f1(base / "e1/metrics.json"), f2(base / "e2/metrics.json");
  const Json m1 = Json::parse(f1), m2 = Json::parse(f2);
  CHECK(m1["hs_psnr_db"].get<double>() != m2["hs_psnr_db"].get<double>());
  // The constant-depth baseline does not depend on the optics.
  CHECK(m1["baseline_constant_depth_rmse_m"].get<double>() == m2["baseline_constant_depth_rmse_m"].get<double>());
}

TEST_CASE("the shipped example captures folder calibrates back to its truth", "[calibration][app]") {
  const fs::path out = fs::temp_directory_path() / "hsd_test_calibrate_example";
  fs::remove_all(out);
  const test::Run r = test::run("hsd_calibrate --config configs/tiny.json --captures data/captures_example --reference "
                                "data/captures_example/truth_psf.pt --out " + out.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  std::ifstream f(out / "mismatch.json");
  const Json m = Json::parse(f);
  CHECK(m["registration"] == "axis");
  CHECK(m["reference_rel_l1_max"].get<double>() < 0.05);
  CHECK(m["rel_l1_mean"].get<double>() > 2 * m["reference_rel_l1_mean"].get<double>());  // the fab error is seen
}
