// Baselines and the all-in-focus control: the training split's median inverse
// depth and the constant-depth errors against a hand computation; an evaluation
// whose "network" outputs the baselines scores exactly the baselines; metrics
// over the valid mask only; the all-in-focus control's PSF is one
// diffraction-limited (Airy) pattern at every band and depth.
#include <catch2/catch.hpp>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "common/config.h"
#include "common/error.h"
#include "data/dataset.h"
#include "data/depth_structure.h"
#include "data/illuminant_augment.h"
#include "data/spectral_moments.h"
#include "data/synthetic_dataset.h"
#include "helpers.h"
#include "model/defocus_likelihood.h"
#include "model/spectral_upsampling.h"
#include "model/spectral_wiener.h"
#include "model/unet.h"
#include "model/wiener_preinverse.h"
#include "optics/all_in_focus.h"
#include "optics/psf_source.h"
#include "optics/depth_distinctness.h"
#include "optics/doe.h"
#include "optics/material.h"
#include "optics/pixel_quadrature.h"
#include "optics/psf.h"
#include "optics/sensor.h"
#include "optics/sensor_image.h"
#include "train/baselines.h"
#include "train/evaluator.h"
#include "train/metrics.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

data::LoadedScene scene_with(const torch::Tensor& depth_m, const torch::Tensor& mask) {
  data::LoadedScene s;
  s.scene.depth_m = depth_m.view({1, depth_m.size(-2), depth_m.size(-1)}).to(torch::kFloat32);
  s.scene.mask = mask.view({1, mask.size(-2), mask.size(-1)}).to(torch::kFloat32);
  s.scene.spectral = torch::zeros({1, depth_m.size(-2), depth_m.size(-1)});
  return s;
}

// A config's optics as evaluate() takes them: the PSF simulator, the sensor,
// the DOE's starting height [N, N] m and the spectral-upsampling map [L, 3].
struct EvalOptics {
  optics::Material material;
  optics::PsfSimulator sim;
  optics::SensorModel sensor;
  torch::Tensor h, w;
  explicit EvalOptics(const Config& cfg)
      : material(optics::Material::load(cfg.optics.material)),
        sim(optics::make_psf_spec(cfg.optics, material, torch::kCPU)),
        sensor(optics::make_sensor_model(cfg.sensor, sim.spec(), cfg.optics.band_width_m())),
        h(optics::initial_height(cfg.optics, material, cfg.seed)),
        w(model::spectral_upsampling_weights(sensor.omega)) {}
};

}  // namespace

TEST_CASE("baselines: the median inverse depth of the valid training pixels, by hand", "[baselines]") {
  // Scene 1: depths 1, 2, 4, 0.5 m with the last pixel masked; scene 2: 0.8 m twice.
  const auto a = scene_with(torch::tensor({1.0, 2.0, 4.0, 0.5}).view({2, 2}), torch::tensor({1.0, 1.0, 1.0, 0.0}).view({2, 2}));
  const auto b = scene_with(torch::tensor({0.8, 0.8}).view({1, 2}), torch::ones({1, 2}));
  // Valid inverse depths: 1, 0.5, 0.25, 1.25, 1.25 -> sorted 0.25 0.5 1 1.25 1.25, median 1.
  CHECK(train::median_inverse_depth({a, b}) == Approx(1.0).epsilon(1e-6));
  // Four values: the lower median (0.5 of 0.25, 0.5, 1, 1.25).
  const auto c = scene_with(torch::tensor({1.0, 2.0, 4.0, 0.8}).view({2, 2}), torch::ones({2, 2}));
  CHECK(train::median_inverse_depth({c}) == Approx(0.5).epsilon(1e-6));
  // No valid pixel: refused.
  const auto none = scene_with(torch::ones({2, 2}), torch::zeros({2, 2}));
  CHECK_THROWS_AS(train::median_inverse_depth({none}), InputError);
  const torch::Tensor z = train::constant_depth_map(torch::zeros({1, 3, 4}), 0.8);
  CHECK(z.sizes() == torch::IntArrayRef({1, 3, 4}));
  CHECK(z.min().item<double>() == Approx(1.25));
  CHECK(z.max().item<double>() == Approx(1.25));
}

TEST_CASE("metrics: PSNR and SSIM over the valid mask ignore the invalid pixels, and NaN is never a best score", "[metrics][baselines]") {
  torch::manual_seed(1);
  const torch::Tensor truth = torch::rand({2, 24, 24});
  torch::Tensor pred = truth + 0.01 * torch::randn({2, 24, 24});
  torch::Tensor mask = torch::ones({1, 24, 24});
  mask.narrow(2, 12, 12).zero_();                 // right half invalid
  pred.narrow(2, 12, 12).fill_(7.0);              // garbage there
  const torch::Tensor left_p = pred.narrow(2, 0, 12), left_t = truth.narrow(2, 0, 12);
  CHECK(train::psnr_db(pred, truth, 1.0, mask) == Approx(train::psnr_db(left_p, left_t, 1.0)).epsilon(1e-9));
  CHECK(train::psnr_db(pred, truth, 1.0) < train::psnr_db(pred, truth, 1.0, mask) - 20.0);
  CHECK(train::ssim(pred, truth, 1.0, mask) > 0.9);
  CHECK(train::ssim(pred, truth, 1.0) < 0.7);
  torch::Tensor nan = pred.clone();
  nan[0][0][0] = std::nan("");
  CHECK_THROWS_AS(train::psnr_db(nan, truth, 1.0, mask), NumericalError);
  CHECK_THROWS_AS(train::ssim(truth, nan, 1.0), NumericalError);
  CHECK_THROWS_WITH(train::psnr_db(nan, truth, 1.0), Catch::Matchers::Contains("NaN at [0, 0, 0]"));
}

TEST_CASE("baselines: a network that outputs the baselines scores exactly the baselines, which match a hand computation",
          "[baselines][eval]") {
  const fs::path root = fs::temp_directory_path() / "hsd_test_baselines";
  fs::remove_all(root);
  const Config cfg = load_config(test::source_path("configs/tiny.json"),
                                 {"data.root=\"" + root.string() + "\"", "data.generator.train_scenes=2",
                                  "data.generator.val_scenes=0", "data.generator.test_scenes=2",
                                  "data.generator.colorchecker=false", "data.generator.width_px=48",
                                  "data.generator.height_px=40", "sensor.noise_std=0.01"});
  data::ensure_dataset(cfg);
  const auto bands = cfg.optics.wavelengths_m();
  const double bw = cfg.optics.band_width_m();
  const auto train_split = data::load_split(root.string(), "train", bands, bw, 1);
  const auto test_split = data::load_split(root.string(), "test", bands, bw, 1);
  // The median by hand: sort every valid inverse depth, take the lower middle.
  std::vector<double> inv;
  for (const auto& s : train_split) {
    const auto z = s.scene.depth_m.contiguous().data_ptr<float>();
    const auto m = s.scene.mask.contiguous().data_ptr<float>();
    for (int64_t i = 0; i < s.scene.depth_m.numel(); ++i)
      if (m[i] > 0.5f) inv.push_back(1.0 / double(z[i]));
  }
  std::sort(inv.begin(), inv.end());
  const double median = inv[(inv.size() - 1) / 2];
  CHECK(train::median_inverse_depth(train_split) == Approx(median).epsilon(1e-12));

  const EvalOptics optics_(cfg);
  const auto& sim = optics_.sim;
  const auto& sensor = optics_.sensor;
  const torch::Tensor& h = optics_.h;
  const torch::Tensor& w = optics_.w;
  // The "network" that answers with the baselines themselves.
  auto trivial = [&](const torch::Tensor& x) {
    return std::make_pair(model::spectral_upsample(w, x), train::constant_depth_map(x.narrow(1, 0, 1), median));
  };
  const train::EvalResult r = train::evaluate(sim, sensor, h, trivial, cfg, "test", (root / "eval").string(), median);
  REQUIRE(r.scenes.size() == 2);
  for (size_t i = 0; i < r.scenes.size(); ++i) {
    const auto& m = r.scenes[i];
    CHECK(m.depth_rmse_m == m.baseline_constant_depth_rmse_m);
    CHECK(m.depth_mae_m == m.baseline_constant_depth_mae_m);
    CHECK(m.hs_psnr_db == m.baseline_upsampling_hs_psnr_db);
    CHECK(m.hs_ssim == m.baseline_upsampling_hs_ssim);
    // The constant's errors by hand over the valid pixels.
    const auto& sc = test_split[i].scene;
    const auto z = sc.depth_m.contiguous().data_ptr<float>();
    const auto mk = sc.mask.contiguous().data_ptr<float>();
    double se = 0, ae = 0, n = 0;
    for (int64_t k = 0; k < sc.depth_m.numel(); ++k)
      if (mk[k] > 0.5f) {
        const double e = 1.0 / median - double(z[k]);
        se += e * e, ae += std::abs(e), n += 1;
      }
    CHECK(m.baseline_constant_depth_rmse_m == Approx(std::sqrt(se / n)).epsilon(1e-5));
    CHECK(m.baseline_constant_depth_mae_m == Approx(ae / n).epsilon(1e-5));
  }
  CHECK(r.mean.baseline_constant_depth_rmse_m ==
        Approx(0.5 * (r.scenes[0].baseline_constant_depth_rmse_m + r.scenes[1].baseline_constant_depth_rmse_m)));
  CHECK(std::isnan(r.mean.network_depth_rmse_m));  // not a fused depth: its readings are not reported
  CHECK(!Json::parse(std::ifstream(root / "eval" / "metrics.json")).contains("network_depth_rmse_m"));
  // A fused depth's two readings are scored alone on the same pixels: a
  // "network" reading the constant and a "reader" reading the upsampling's
  // first band as metres score as those maps do.
  auto parts = [&](const torch::Tensor& x) {
    const torch::Tensor c = train::constant_depth_map(x.narrow(1, 0, 1), median);
    return train::Reconstruction(model::spectral_upsample(w, x), 0.5 * (c + 1.0), c, torch::ones_like(c));
  };
  const train::EvalResult rp = train::evaluate(sim, sensor, h, parts, cfg, "test", (root / "eval_p").string(), median);
  for (const auto& m : rp.scenes) {
    CHECK(m.network_depth_rmse_m == m.baseline_constant_depth_rmse_m);
    CHECK(m.network_depth_mae_m == m.baseline_constant_depth_mae_m);
    CHECK(std::isfinite(m.fused_reader_depth_rmse_m));
    CHECK(m.fused_reader_depth_rmse_m != m.depth_rmse_m);
  }
  CHECK(rp.mean.network_depth_rmse_m == Approx(r.mean.baseline_constant_depth_rmse_m));
  const Json jp = Json::parse(std::ifstream(root / "eval_p" / "metrics.json"));
  CHECK(jp.contains("network_depth_rmse_m"));
  CHECK(jp["scenes"][0].contains("fused_reader_depth_mae_m"));
  // The Wiener baseline: a "network" answering with the layers' mean Wiener
  // deconvolution, upsampled, scores exactly it; it is not the upsampling's.
  // Its depth, the classical depth-from-defocus reader's map, scores exactly
  // baseline_defocus_*.
  const torch::Tensor rgb_psf = model::camera_rgb_psfs(optics::imaging_psf_stack(sim, h, nullptr), sensor.omega);
  auto wiener = [&](const torch::Tensor& x) {
    return std::make_pair(
        train::wiener_upsampling_cube(x, rgb_psf, cfg.model.preinverse_reg, w),
        model::defocus_layer_depth(model::defocus_cost_volume(x, rgb_psf, train::kDefocusBaseline), cfg.optics.depths_m).unsqueeze(1));
  };
  const train::EvalResult rw = train::evaluate(sim, sensor, h, wiener, cfg, "test", (root / "eval_w").string(), median);
  for (const auto& m : rw.scenes) {
    CHECK(m.hs_psnr_db == m.baseline_wiener_hs_psnr_db);
    CHECK(m.hs_ssim == m.baseline_wiener_hs_ssim);
    CHECK(m.baseline_wiener_hs_psnr_db != m.baseline_upsampling_hs_psnr_db);
    CHECK(m.depth_rmse_m == m.baseline_defocus_depth_rmse_m);
    CHECK(m.depth_mae_m == m.baseline_defocus_depth_mae_m);
    CHECK(m.baseline_defocus_depth_rmse_m != m.baseline_constant_depth_rmse_m);
  }
  // A learned spectral map (model.spectral_map = "learned"): a "network"
  // answering with that map on its residual base (here the image) scores
  // exactly model_base_*, which is absent when no map is given.
  CHECK(std::isnan(r.mean.model_base_hs_psnr_db));
  const torch::Tensor map = w * (1.0 + 0.3 * torch::rand_like(w));
  auto mapped = [&](const torch::Tensor& x) {
    return std::make_pair(model::spectral_upsample(map, x), train::constant_depth_map(x.narrow(1, 0, 1), median));
  };
  const train::EvalResult rm =
      train::evaluate(sim, sensor, h, mapped, cfg, "test", (root / "eval_m").string(), median, nullptr, {}, map);
  for (const auto& m : rm.scenes) {
    CHECK(m.hs_psnr_db == m.model_base_hs_psnr_db);
    CHECK(m.hs_ssim == m.model_base_hs_ssim);
    CHECK(m.model_base_hs_psnr_db != m.baseline_upsampling_hs_psnr_db);
  }
  CHECK(Json::parse(std::ifstream(root / "eval_m" / "metrics.json")).contains("model_base_hs_psnr_db"));
  // The spectral Wiener baseline: its prior from the training split (the
  // moments as the trainer lights them); a "network" answering with the LMMSE
  // cube scores exactly it; absent without a prior.
  CHECK(std::isnan(r.mean.baseline_spectral_wiener_hs_psnr_db));
  const model::SpectralPrior prior = train::training_spectral_prior(train_split, cfg, sensor);
  const data::IlluminantBank bank(cfg.data.illuminants, bands, bw);
  const data::SpectralMoments mo = data::radiance_moments(train_split, bank.spectra(), cfg.data.intensity_min, cfg.data.intensity_max);
  CHECK((prior.mean - mo.mean.to(torch::kFloat32)).abs().max().item<double>() < 1e-7);
  CHECK(prior.noise_var > cfg.sensor.noise_std * cfg.sensor.noise_std * 0.999);  // read noise at least
  const torch::Tensor band_psf = optics::imaging_psf_stack(sim, h, nullptr);
  // Its depth, the spectral depth-from-defocus reader's map, scores exactly baseline_spectral_defocus_*.
  auto lmmse = [&](const torch::Tensor& x) {
    return std::make_pair(model::spectral_wiener_cube(x, band_psf, sensor.omega, prior).to(torch::kFloat32),
                          model::defocus_layer_depth(model::spectral_defocus_cost_volume(x, band_psf, sensor.omega, prior,
                                                                                         train::kSpectralDefocusWindowPx),
                                                     cfg.optics.depths_m)
                              .unsqueeze(1));
  };
  const train::EvalResult rs = train::evaluate(sim, sensor, h, lmmse, cfg, "test", (root / "eval_s").string(), median,
                                               nullptr, {}, {}, &prior);
  for (const auto& m : rs.scenes) {
    CHECK(m.hs_psnr_db == m.baseline_spectral_wiener_hs_psnr_db);
    CHECK(m.hs_ssim == m.baseline_spectral_wiener_hs_ssim);
    CHECK(m.baseline_spectral_wiener_hs_psnr_db != m.baseline_wiener_hs_psnr_db);
    CHECK(m.depth_rmse_m == m.baseline_spectral_defocus_depth_rmse_m);
    CHECK(m.depth_mae_m == m.baseline_spectral_defocus_depth_mae_m);
  }
  CHECK(std::isnan(r.mean.baseline_spectral_defocus_depth_rmse_m));
  CHECK(std::isnan(r.mean.depth_known_spectral_wiener_hs_psnr_db));
  // The depth-known reference: a "network" that takes each pixel's cube from
  // the plain spectral Wiener cube of its true rendering layer's PSFs alone
  // (independently of model/layered_spectral_wiener.h) scores it to rounding
  // (the scenes come in the split's order).
  size_t next = 0;
  auto depth_known = [&](const torch::Tensor& x) {
    const torch::Tensor d = test_split.at(next++).scene.depth_m.unsqueeze(0);
    const torch::Tensor layer = optics::nearest_layer(d, cfg.optics.depths_m);  // [1, 1, H, W]
    torch::Tensor cube = torch::zeros({1, band_psf.size(0), x.size(2), x.size(3)});
    for (int64_t z = 0; z < band_psf.size(1); ++z) {
      const torch::Tensor cz = model::spectral_wiener_cube(x, band_psf.narrow(1, z, 1), sensor.omega, prior).to(torch::kFloat32);
      cube = torch::where(layer == z, cz, cube);
    }
    return std::make_pair(cube, d);
  };
  const train::EvalResult rk = train::evaluate(sim, sensor, h, depth_known, cfg, "test", (root / "eval_k").string(),
                                               median, nullptr, {}, {}, &prior);
  for (const auto& m : rk.scenes) {
    CHECK(m.hs_psnr_db == Approx(m.depth_known_spectral_wiener_hs_psnr_db).margin(1e-4));
    CHECK(m.depth_known_spectral_wiener_hs_psnr_db != m.baseline_spectral_wiener_hs_psnr_db);
  }
  CHECK(Json::parse(std::ifstream(root / "eval_k" / "metrics.json")).contains("reference_depth_known_spectral_wiener_hs_psnr_db"));
  CHECK(Json::parse(std::ifstream(root / "eval_s" / "metrics.json")).contains("baseline_spectral_wiener_hs_psnr_db"));
  CHECK(Json::parse(std::ifstream(root / "eval_s" / "metrics.json"))["scenes"][0].contains("baseline_spectral_defocus_depth_rmse_m"));
  // metrics.json carries the contract's baseline keys, mean and per scene.
  const Json j = Json::parse(std::ifstream(root / "eval" / "metrics.json"));
  CHECK_FALSE(j.contains("model_base_hs_psnr_db"));
  for (const char* k : {"baseline_constant_depth_rmse_m", "baseline_constant_depth_mae_m", "baseline_upsampling_hs_psnr_db",
                        "baseline_upsampling_hs_ssim", "baseline_wiener_hs_psnr_db", "baseline_wiener_hs_ssim",
                        "baseline_defocus_depth_rmse_m", "baseline_defocus_depth_mae_m"}) {
    CHECK(j.contains(k));
    CHECK(j["scenes"][0].contains(k));
  }
  CHECK(j.at("depth_rmse_m") == j.at("baseline_constant_depth_rmse_m"));
  // The resolution oracle: one RMSE per window, mean and per scene, and the model's effective resolution.
  REQUIRE(j.contains("reference_oracle_depth_rmse_m"));
  CHECK(j["reference_oracle_depth_rmse_m"].size() == train::kOracleWindowsPx.size());
  CHECK(j["scenes"][0]["reference_oracle_depth_rmse_m"]["15"].get<double>() == Approx(r.scenes[0].oracle_depth_rmse_m[3]));
  CHECK(j.contains("depth_effective_resolution_px"));
  const auto& sc0 = test_split[0].scene;
  const train::DepthErrors o15 =
      train::depth_errors(data::box_oracle_depth_map(sc0.depth_m, sc0.mask, 15), sc0.depth_m, sc0.mask);
  CHECK(r.scenes[0].oracle_depth_rmse_m[3] == Approx(o15.rmse_m).epsilon(1e-9));
  // The layer oracle: in metrics.json, mean and per scene, equal to its map's
  // errors, and never worse than the constant (a per-layer mean beats one constant).
  REQUIRE(j.contains("reference_layer_oracle_depth_rmse_m"));
  CHECK(j["scenes"][1].contains("reference_layer_oracle_depth_mae_m"));
  const train::DepthErrors lo =
      train::depth_errors(train::layer_oracle_depth_map(sc0.depth_m, sc0.mask, cfg.optics.depths_m), sc0.depth_m, sc0.mask);
  CHECK(r.scenes[0].layer_oracle_depth_rmse_m == Approx(lo.rmse_m).epsilon(1e-9));
  for (const auto& m : r.scenes) CHECK(m.layer_oracle_depth_rmse_m <= m.baseline_constant_depth_rmse_m + 1e-9);
}

TEST_CASE("evaluation: the interior metrics score the valid pixels beyond the rendering margin, by hand", "[baselines][eval]") {
  const fs::path root = fs::temp_directory_path() / "hsd_test_interior";
  fs::remove_all(root);
  const std::vector<std::string> sets{"data.root=\"" + root.string() + "\"", "data.generator.train_scenes=2",
                                      "data.generator.val_scenes=0", "data.generator.test_scenes=2",
                                      "data.generator.colorchecker=false", "data.generator.width_px=48",
                                      "data.generator.height_px=40", "sensor.noise_std=0.01"};
  auto with = [&](const std::string& extra) {
    std::vector<std::string> v = sets;
    v.push_back(extra);
    return load_config(test::source_path("configs/tiny.json"), v);
  };
  const Config cfg = with("data.render_margin_px=8");
  data::ensure_dataset(cfg);
  const auto bands = cfg.optics.wavelengths_m();
  const double bw = cfg.optics.band_width_m();
  const auto train_split = data::load_split(root.string(), "train", bands, bw, 1);
  const auto test_split = data::load_split(root.string(), "test", bands, bw, 1);
  const double median = train::median_inverse_depth(train_split);
  const EvalOptics o(cfg);
  // A "network" answering with the baselines inside the 8-px band and garbage in it.
  auto banded = [&](const torch::Tensor& x) {
    torch::Tensor cube = torch::full({1, o.w.size(0), x.size(2), x.size(3)}, 5.0);
    torch::Tensor depth = torch::full({1, 1, x.size(2), x.size(3)}, 50.0);
    const int64_t H = x.size(2) - 16, W = x.size(3) - 16;
    cube.narrow(2, 8, H).narrow(3, 8, W).copy_(model::spectral_upsample(o.w, x).narrow(2, 8, H).narrow(3, 8, W));
    depth.narrow(2, 8, H).narrow(3, 8, W).fill_(1.0 / median);
    return std::make_pair(cube, depth);
  };
  const train::EvalResult r = train::evaluate(o.sim, o.sensor, o.h, banded, cfg, "test", (root / "eval").string(), median);
  REQUIRE(r.scenes.size() == 2);
  for (size_t i = 0; i < r.scenes.size(); ++i) {
    const auto& m = r.scenes[i];
    CHECK(m.interior_margin_px == 8);
    // Inside, the answer is the baselines': equal to the bit; outside it is garbage.
    CHECK(m.interior_hs_psnr_db == m.interior_baseline_upsampling_hs_psnr_db);
    CHECK(m.interior_depth_rmse_m == m.interior_baseline_constant_depth_rmse_m);
    CHECK(m.hs_psnr_db < m.baseline_upsampling_hs_psnr_db - 3.0);
    CHECK(m.depth_rmse_m > 10.0);
    CHECK(std::isnan(m.interior_model_base_hs_psnr_db));  // no base given: not reported
    // The constant's interior RMSE and the interior's share by hand: rows 8..31, columns 8..39.
    const auto& sc = test_split[i].scene;
    double se = 0, n = 0, n_valid = 0;
    for (int64_t y = 0; y < 40; ++y)
      for (int64_t x = 0; x < 48; ++x) {
        if (sc.mask[0][y][x].item<float>() <= 0.5f) continue;
        n_valid += 1;
        if (y < 8 || y >= 32 || x < 8 || x >= 40) continue;
        const double e = 1.0 / median - double(sc.depth_m[0][y][x].item<float>());
        se += e * e, n += 1;
      }
    REQUIRE(n > 0);
    CHECK(m.interior_baseline_constant_depth_rmse_m == Approx(std::sqrt(se / n)).epsilon(1e-5));
    CHECK(m.interior_fraction == Approx(n / n_valid).epsilon(1e-12));
  }
  CHECK(r.mean.interior_scenes == 2);
  CHECK(r.mean.interior_hs_psnr_db == Approx(0.5 * (r.scenes[0].interior_hs_psnr_db + r.scenes[1].interior_hs_psnr_db)));
  const Json j = Json::parse(std::ifstream(root / "eval" / "metrics.json"));
  CHECK(j.at("interior_margin_px") == 8);
  CHECK(j.at("interior_scenes") == 2);
  for (const char* k : {"interior_fraction", "interior_hs_psnr_db", "interior_baseline_upsampling_hs_psnr_db",
                        "interior_depth_rmse_m", "interior_baseline_constant_depth_rmse_m"}) {
    CHECK(j.contains(k));
    CHECK(j["scenes"][1].contains(k));
  }
  CHECK_FALSE(j.contains("interior_model_base_hs_psnr_db"));
  std::ifstream rep(root / "eval" / "report.md");
  const std::string md((std::istreambuf_iterator<char>(rep)), std::istreambuf_iterator<char>());
  CHECK(md.find("The interior (interior_*: the valid pixels at least 8 px") != std::string::npos);
  // No margin: the interior is the whole valid scene.
  auto trivial = [&](const torch::Tensor& x) {
    return std::make_pair(model::spectral_upsample(o.w, x), train::constant_depth_map(x.narrow(1, 0, 1), median));
  };
  const train::EvalResult r0 =
      train::evaluate(o.sim, o.sensor, o.h, trivial, with("data.render_margin_px=0"), "test", (root / "eval0").string(), median);
  for (const auto& m : r0.scenes) {
    CHECK(m.interior_hs_psnr_db == m.hs_psnr_db);
    CHECK(m.interior_depth_rmse_m == m.depth_rmse_m);
    CHECK(m.interior_fraction == 1.0);
  }
  // A margin of more than half the scene's height: no interior, no keys, and the report says so.
  const train::EvalResult r20 =
      train::evaluate(o.sim, o.sensor, o.h, trivial, with("data.render_margin_px=20"), "test", (root / "eval20").string(), median);
  CHECK(r20.mean.interior_scenes == 0);
  CHECK(std::isnan(r20.mean.interior_hs_psnr_db));
  CHECK(r20.mean.interior_fraction == 0.0);
  const Json j20 = Json::parse(std::ifstream(root / "eval20" / "metrics.json"));
  CHECK_FALSE(j20.contains("interior_hs_psnr_db"));
  CHECK_FALSE(j20["scenes"][0].contains("interior_depth_rmse_m"));
  std::ifstream rep20(root / "eval20" / "report.md");
  const std::string md20((std::istreambuf_iterator<char>(rep20)), std::istreambuf_iterator<char>());
  CHECK(md20.find("no scene has one") != std::string::npos);
}

TEST_CASE("resolution oracle: box means of inverse depth over valid pixels, by hand, and the effective resolution",
          "[baselines]") {
  // 3 x 4 depth map: two columns at 0.5 m (1/z = 2), two at 2 m (1/z = 0.5).
  torch::Tensor z = torch::tensor({0.5, 0.5, 2.0, 2.0}, torch::kFloat64).repeat({3, 1}).unsqueeze(0);  // [1, 3, 4]
  torch::Tensor mask = torch::ones_like(z);
  const torch::Tensor o = data::box_oracle_depth_map(z, mask, 3);
  CHECK(o[0][1][1].item<double>() == Approx(1.0 / 1.5));        // 6 pixels at 2 and 3 at 0.5: mean 1.5
  CHECK(o[0][0][0].item<double>() == Approx(0.5));              // the box clipped at the corner: all at 2
  CHECK(o[0][0][2].item<double>() == Approx(1.0));              // (2·2 + 4·0.5) / 6 = 1
  mask[0][1][2] = 0;                                            // an invalid pixel leaves the mean
  CHECK(data::box_oracle_depth_map(z, mask, 3)[0][1][1].item<double>() == Approx(8.0 / 13.0));  // (6·2 + 2·0.5) / 8
  // w = 1 is the truth; a constant depth is its own oracle at every window.
  CHECK(torch::equal(data::box_oracle_depth_map(z, torch::ones_like(z), 1), z));
  const torch::Tensor flat = torch::full({1, 6, 7}, 1.3, torch::kFloat64);
  CHECK(torch::allclose(data::box_oracle_depth_map(flat, torch::ones_like(flat), 5), flat));
  CHECK_THROWS_AS(data::box_oracle_depth_map(z, mask, 4), InputError);
  CHECK_THROWS_AS(data::box_oracle_depth_map(z, mask.squeeze(0), 3), InputError);
  // Effective resolution: linear in log w between the bracketing windows.
  const std::vector<int64_t> w{3, 9, 27};
  const std::vector<double> r{0.1, 0.2, 0.4};
  CHECK(train::effective_resolution_px(w, r, 0.3) == Approx(9.0 * std::sqrt(3.0)));
  CHECK(train::effective_resolution_px(w, r, 0.2) == Approx(9.0));
  CHECK(train::effective_resolution_px(w, r, 0.05) == 3.0);
  CHECK(std::isinf(train::effective_resolution_px(w, r, 0.5)));
  CHECK_THROWS_AS(train::effective_resolution_px({3}, {0.1, 0.2}, 0.1), InputError);
}

TEST_CASE("layer oracle: each valid pixel at the mean depth of its map's pixels in the same rendering layer, by hand",
          "[baselines]") {
  // Layers at 0.5, 1 and 2 m (inverse depth 2, 1, 0.5). Nearest in inverse depth:
  // 0.45 m (2.22) and 0.6 m (1.67) -> 0.5 m; 0.9 m (1.11) -> 1 m; 1.6 m (0.625)
  // and 2.5 m (0.4) -> 2 m.
  const std::vector<double> layers{0.5, 1.0, 2.0};
  torch::Tensor z = torch::tensor({0.45, 0.6, 0.9, 1.6, 2.5, 1.6}, torch::kFloat64).view({1, 1, 2, 3});
  torch::Tensor mask = torch::ones_like(z);
  torch::Tensor o = train::layer_oracle_depth_map(z, mask, layers);
  CHECK(o[0][0][0][0].item<double>() == Approx(0.525));   // (0.45 + 0.6) / 2
  CHECK(o[0][0][0][1].item<double>() == Approx(0.525));
  CHECK(o[0][0][0][2].item<double>() == Approx(0.9));     // alone in its layer: exact
  CHECK(o[0][0][1][0].item<double>() == Approx(1.9));     // (1.6 + 2.5 + 1.6) / 3
  CHECK(o[0][0][1][1].item<double>() == Approx(1.9));
  // An invalid pixel leaves its layer's mean and keeps its own depth.
  mask[0][0][1][1] = 0;
  o = train::layer_oracle_depth_map(z, mask, layers);
  CHECK(o[0][0][1][0].item<double>() == Approx(1.6));
  CHECK(o[0][0][1][1].item<double>() == Approx(2.5));
  // Each map of a batch has its own means; one layer per pixel is the truth.
  const torch::Tensor two = torch::stack({z[0], (z[0] * 0 + 2.0)});  // [2, 1, 2, 3]
  const torch::Tensor o2 = train::layer_oracle_depth_map(two, torch::ones_like(two), layers);
  CHECK(o2[0][0][0][2].item<double>() == Approx(0.9));
  CHECK(torch::allclose(o2[1], two[1]));
  const torch::Tensor exact = torch::tensor({0.5, 1.0, 2.0}, torch::kFloat64).view({1, 1, 1, 3});
  CHECK(torch::allclose(train::layer_oracle_depth_map(exact, torch::ones_like(exact), layers), exact));
  CHECK_THROWS_AS(train::layer_oracle_depth_map(z, mask.squeeze(0), layers), InputError);
}

TEST_CASE("heads started at the baselines: the untrained network outputs exactly the upsampling cube and the constant depth",
          "[baselines][model]") {
  torch::manual_seed(3);
  model::NetOptions o;
  o.bands = 5, o.base_width = 4, o.levels = 2, o.norm = NormKind::group, o.depth_min_m = 0.4, o.depth_max_m = 2.5;
  const torch::Tensor w = torch::rand({5, 3});
  model::HsdNet net(o, w);
  const torch::Tensor x = torch::rand({2, 3, 20, 24});
  const double inv = 1.0 / 0.9;  // 0.9 m
  const model::NetOutput before = net->forward(x);
  CHECK((before.hs - model::spectral_upsample(w, x)).abs().max().item<double>() > 1e-3);  // random heads: not the baseline
  net->start_at_baselines(inv);
  const model::NetOutput out = net->forward(x);
  CHECK((out.hs - model::spectral_upsample(w, x)).abs().max().item<double>() == 0.0);
  CHECK((out.depth_m - 0.9).abs().max().item<double>() < 1e-5);
  // The first update moves both heads: gradients reach them although their weights are zero.
  const torch::Tensor loss = (out.hs - 1.0).abs().mean() + (out.inv_depth - 2.0).abs().mean();
  loss.backward();
  for (const auto& p : net->named_parameters())
    if (p.key().rfind("head_", 0) == 0 && p.key().find("weight") != std::string::npos) {
      INFO(p.key());
      CHECK(p.value().grad().abs().sum().item<double>() > 0.0);
    }
}

TEST_CASE("all-in-focus control: one diffraction-limited Airy pattern at every band and depth", "[baselines][psf][closed-form]") {
  const Config cfg = load_config(test::source_path("configs/quick.json"), {});
  const auto material = optics::Material::load(cfg.optics.material);
  const torch::Tensor p = optics::all_in_focus_psf(cfg.optics, material, torch::kCPU);
  const int64_t L = int64_t(cfg.optics.wavelengths_nm.size()), Z = int64_t(cfg.optics.depths_m.size());
  const int64_t P = cfg.optics.psf_size;
  REQUIRE(p.sizes() == torch::IntArrayRef({L, Z, P, P}));
  for (int64_t l = 0; l < L; ++l)
    for (int64_t z = 0; z < Z; ++z) CHECK(p[l][z].equal(p[0][0]));  // the same pattern, bit for bit
  CHECK(p[0][0].sum().item<double>() == Approx(1.0).epsilon(1e-5));
  // Against the Airy pattern (2 J1(v)/v)², v = π D r / (λ0 s), integrated over
  // each pixel (8x8 Gauss rule) and normalised to the window like the PSF.
  const double lambda = cfg.optics.doe.design_wavelength_m, s = cfg.optics.sensor_distance_m;
  const double D = cfg.optics.aperture_diameter_m, pitch = cfg.optics.pixel_pitch_m;
  const auto q = optics::gauss_legendre(8);
  torch::Tensor airy = torch::zeros({P, P}, torch::kFloat64);
  for (int64_t i = 0; i < P; ++i)
    for (int64_t j = 0; j < P; ++j) {
      double sum = 0.0;
      for (size_t a = 0; a < q.nodes.size(); ++a)
        for (size_t b = 0; b < q.nodes.size(); ++b) {
          const double r = std::hypot((double(j - P / 2) + q.nodes[a]) * pitch, (double(i - P / 2) + q.nodes[b]) * pitch);
          const double v = M_PI * D * r / (lambda * s);
          const double amp = v < 1e-9 ? 1.0 : 2.0 * std::cyl_bessel_j(1.0, v) / v;
          sum += q.weights[a] * q.weights[b] * amp * amp;
        }
      airy[i][j] = sum;
    }
  airy = airy / airy.sum();
  const double rel_l1 = ((p[0][0].to(torch::kFloat64) - airy).abs().sum() / airy.sum()).item<double>();
  INFO("relative L1 to the Airy pattern: " << rel_l1);
  CHECK(rel_l1 < 0.01);
  // And it is not the DOE's: the quick config's Fresnel PSFs change with depth.
  const optics::PsfSimulator sim(optics::make_psf_spec(cfg.optics, material, torch::kCPU));
  const torch::Tensor doe = sim.compute(optics::initial_height(cfg.optics, material, 0)).psf;
  CHECK((doe[4][0] - doe[4][1]).abs().sum().item<double>() > 0.1);
}

TEST_CASE("shipped configs: the quick start keeps most of its light in its window and every band tells the depths apart",
          "[config][psf]") {
  auto measure = [](const std::vector<std::string>& overrides) {
    const Config cfg = load_config(test::source_path("configs/quick.json"), overrides);
    const auto material = optics::Material::load(cfg.optics.material);
    const optics::PsfSimulator sim(optics::make_psf_spec(cfg.optics, material, torch::kCPU));
    const optics::PsfStack s = sim.compute(optics::initial_height(cfg.optics, material, cfg.seed));
    const auto d = optics::depth_distinctness(s.psf);
    return std::make_tuple(s.energy_in_window.min().item<double>(), s.energy_in_window.mean().item<double>(),
                           *std::min_element(d.per_band.begin(), d.per_band.end()));
  };
  const auto [emin, emean, dmin] = measure({});
  INFO("energy in window: min " << emin << ", mean " << emean << "; smallest depth distance of a band " << dmin);
  CHECK(emin >= 0.35);
  CHECK(emean >= 0.7);
  CHECK(dmin >= 0.05);
  // The earlier quick optics (31-px window, Fresnel focused at the layers'
  // harmonic middle) failed both: light lost, and 550 nm blind to depth.
  const auto [emin0, emean0, dmin0] = measure({"optics.psf_size=31", "optics.doe.design_depth_m=0"});
  CHECK(emin0 < 0.2);
  CHECK(dmin0 < 0.03);
}
