// The data module: band resampling by integration, illuminant augmentation
// (D65 × perfect white = D65, the 29 illuminants), the manifest and its bad
// cases, parallel deterministic loading, the patch sampler (never an invalid
// pixel, deterministic, depth coverage, flips/rotations), the scene generator
// (deterministic, varied, in range; the ColorChecker layout) and RGB lifting.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "common/error.h"
#include "common/log.h"
#include "data/band_resample.h"
#include "data/dataset.h"
#include "data/illuminant_augment.h"
#include "data/manifest.h"
#include "data/patch_sampler.h"
#include "data/preview.h"
#include "data/reflectance_library.h"
#include "data/rgbd_import.h"
#include "data/scene_generator.h"
#include "data/synthetic_dataset.h"
#include "helpers.h"
#include "optics/spectrum.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {
std::vector<double> nm(std::initializer_list<double> v) {
  std::vector<double> out;
  for (double x : v) out.push_back(x * 1e-9);
  return out;
}
data::SpectralScene flat_scene(const std::vector<double>& w, int64_t H, int64_t W, double value, double depth) {
  data::SpectralScene s;
  s.wavelengths_m = w;
  s.spectral = torch::full({int64_t(w.size()), H, W}, value);
  s.depth_m = torch::full({1, H, W}, depth);
  s.mask = torch::ones({1, H, W});
  return s;
}
GeneratorConfig small_generator() {
  GeneratorConfig g;
  g.width_px = 96;
  g.height_px = 72;
  return g;
}
}  // namespace

TEST_CASE("data: band resampling integrates the piecewise-linear spectrum exactly", "[data]") {
  const auto in = nm({400, 410, 420, 430, 440, 450, 460, 470, 480, 490, 500});
  // A linear spectrum s(λ) = 0.1 + 0.002 (λ − 400 nm): a band mean is its value at the centre.
  torch::Tensor s = torch::empty({int64_t(in.size())}, torch::kFloat64);
  for (size_t i = 0; i < in.size(); ++i) s[int64_t(i)] = 0.1 + 0.002 * (in[i] * 1e9 - 400);
  const auto out = nm({412.5, 433, 455, 487});
  const torch::Tensor R = data::band_resampling_matrix(in, out, 7e-9, "test");
  const torch::Tensor r = torch::mv(R, s);
  for (size_t b = 0; b < out.size(); ++b) CHECK(r[int64_t(b)].item<double>() == Approx(0.1 + 0.002 * (out[b] * 1e9 - 400)).epsilon(1e-12));
  // Rows sum to 1 (constants preserved), also for bands straddling an end.
  const torch::Tensor R2 = data::band_resampling_matrix(in, nm({402, 498}), 10e-9, "test");
  CHECK((R2.sum(1) - 1).abs().max().item<double>() < 1e-12);
  // A curved spectrum: the exact mean of the interpolant, checked on a fine grid.
  const torch::Tensor q = torch::rand({int64_t(in.size())}, torch::kFloat64);
  const double fine = [&] {
    double acc = 0;
    const int n = 20000;
    for (int k = 0; k < n; ++k) {
      const double x = 430 + 20.0 * (k + 0.5) / n;  // band 440 ± 10 nm
      const size_t i = size_t((x - 400) / 10);
      const double a = (x - 400 - 10.0 * double(i)) / 10.0;
      acc += (1 - a) * q[int64_t(i)].item<double>() + a * q[int64_t(i + 1)].item<double>();
    }
    return acc / n;
  }();
  CHECK(torch::mv(data::band_resampling_matrix(in, nm({440}), 20e-9, "test"), q).item<double>() == Approx(fine).epsilon(1e-7));
  // Out of range: refused naming the file and the band.
  try {
    data::band_resampling_matrix(in, nm({520}), 10e-9, "scene.exr");
    FAIL("no error");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("scene.exr") && Catch::Contains("520.0 nm"));
  }
  // Same bands: unchanged and no warning; other bands: resampled with one warning.
  const int warnings = log::warning_count();
  const data::SpectralScene sc = flat_scene(in, 4, 5, 0.3, 1.0);
  CHECK(data::resample_scene_bands(sc, in, 10e-9, "x.exr").spectral.equal(sc.spectral));
  CHECK(log::warning_count() == warnings);
  const data::SpectralScene rs = data::resample_scene_bands(sc, out, 7e-9, "x.exr");
  CHECK(log::warning_count() == warnings + 1);
  CHECK(rs.spectral.size(0) == 4);
  CHECK((rs.spectral - 0.3).abs().max().item<double>() < 1e-6);
}

TEST_CASE("data: D65 times a perfect white is D65 and the 29 illuminants load", "[data]") {
  const auto w = nm({420, 450, 480, 510, 540, 570, 600, 630, 660});
  const data::IlluminantBank bank(default_augmentation_illuminants(), w, 10e-9);
  REQUIRE(bank.size() == 29);
  CHECK((bank.spectra().amax(1) - 1).abs().max().item<double>() < 1e-6);  // each scaled to max 1
  const int64_t d65 = std::find(bank.names().begin(), bank.names().end(), "D65") - bank.names().begin();
  const torch::Tensor white = torch::ones({int64_t(w.size()), 3, 4});
  const torch::Tensor lit = data::light_reflectance(white, bank.spectrum(d65));
  const torch::Tensor ref = optics::illuminant_bands("D65", w, 10e-9);
  CHECK((lit - ref.view({-1, 1, 1})).abs().max().item<double>() < 1e-7);
  // Scaling and the batched layout.
  CHECK((data::light_reflectance(white.unsqueeze(0), ref, 0.5)[0] - 0.5 * ref.view({-1, 1, 1})).abs().max().item<double>() < 1e-7);
  // The illuminants differ (no duplicates in the set).
  const torch::Tensor S = bank.spectra().to(torch::kFloat64);
  const torch::Tensor dist = torch::cdist(S, S) + torch::eye(29, torch::kFloat64) * 10;
  CHECK(dist.min().item<double>() > 0.02);
  try {
    data::IlluminantBank({"D65", "D66"}, w, 10e-9);
    FAIL("no error");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("data.illuminants[1]") && Catch::Contains("D66"));
  }
}

TEST_CASE("data: manifests round-trip and bad manifests are refused naming the entry", "[data]") {
  const fs::path dir = fs::temp_directory_path() / "hsd_test_manifest";
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ofstream(dir / "a.exr") << "x";
  std::ofstream(dir / "b.exr") << "x";
  data::Manifest m;
  m.wavelengths_nm = {450, 550};
  m.band_width_nm = 100;
  m.scenes = {{"a.exr", "train", "first"}, {"b.exr", "test", ""}};
  data::write_manifest(dir.string(), m);
  const data::Manifest r = data::read_manifest(dir.string());
  REQUIRE(r.scenes.size() == 2);
  CHECK(r.scenes[0].notes == "first");
  CHECK(r.split("test").size() == 1);
  CHECK(r.wavelengths_nm == m.wavelengths_nm);
  auto refused = [&](const std::string& json, const std::string& needle) {
    std::ofstream(dir / "manifest.json") << json;
    try {
      data::read_manifest(dir.string());
      return std::string("accepted");
    } catch (const InputError& e) {
      const std::string w = e.what();
      return w.find("manifest.json") != std::string::npos && w.find(needle) != std::string::npos ? std::string("ok") : w;
    }
  };
  CHECK(refused(R"({"scenes":[{"file":"a.exr","split":"training"}]})", "scenes[0].split") == "ok");
  CHECK(refused(R"({"scenes":[{"file":"c.exr","split":"train"}]})", "missing file c.exr") == "ok");
  CHECK(refused(R"({"scenes":[{"file":"a.exr","split":"train"},{"file":"a.exr","split":"val"}]})", "twice") == "ok");
  CHECK(refused(R"({"scenes":[{"file":"/etc/passwd","split":"train"}]})", "relative path") == "ok");
  CHECK(refused(R"({"scenes": 3})", "scenes") == "ok");
  CHECK(refused("{not json", "invalid JSON") == "ok");
  CHECK(refused(R"({"scenes":[]})", "no scenes") == "ok");
  fs::remove(dir / "manifest.json");
  CHECK_THROWS_AS(data::read_manifest(dir.string()), InputError);
}

TEST_CASE("data: loading is parallel and deterministic and resamples other bands", "[data]") {
  const fs::path dir = fs::temp_directory_path() / "hsd_test_loader";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto w = nm({450, 550, 650});
  data::Manifest m;
  for (int i = 0; i < 5; ++i) {
    const std::string f = "s" + std::to_string(i) + ".exr";
    data::SpectralScene s = flat_scene(i == 3 ? nm({440, 500, 560, 620, 680}) : w, 6, 7, 0.1 * (i + 1), 1.0 + i);
    data::write_scene_exr((dir / f).string(), s);
    m.scenes.push_back({f, i == 4 ? "val" : "train", ""});
  }
  data::write_manifest(dir.string(), m);
  const auto a = data::load_split(dir.string(), "train", w, 10e-9, 3);
  REQUIRE(a.size() == 4);
  for (size_t i = 0; i < 4; ++i) {
    CHECK(a[i].file == "s" + std::to_string(i) + ".exr");
    CHECK(a[i].scene.spectral.size(0) == 3);
    CHECK(a[i].scene.spectral.mean().item<double>() == Approx(0.1 * double(i + 1)).epsilon(1e-3));
  }
  const auto serial = data::load_split(dir.string(), "train", w, 10e-9, 1);
  for (size_t i = 0; i < 4; ++i) CHECK(serial[i].scene.spectral.equal(a[i].scene.spectral));  // same with 1 or 3 threads
  CHECK(data::load_split(dir.string(), "val", w, 10e-9, 2).size() == 1);
  CHECK_THROWS_AS(data::load_split(dir.string(), "test", w, 10e-9, 2), InputError);
  // A broken scene is reported by name.
  std::ofstream(dir / "s2.exr", std::ios::trunc) << "truncated";
  try {
    data::load_split(dir.string(), "all", w, 10e-9, 3);
    FAIL("no error");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("s2.exr"));
  }
}

TEST_CASE("data: the patch sampler never returns an invalid pixel and covers the depth range", "[data]") {
  // Two scenes: a depth ramp with invalid blobs, and one too small for a patch.
  const auto w = nm({450, 550, 650});
  std::vector<data::LoadedScene> scenes(2);
  const int64_t H = 80, W = 120, S = 24;
  data::SpectralScene s = flat_scene(w, H, W, 0.5, 1.0);
  s.depth_m = (0.4 + 2.0 * torch::arange(W, torch::kFloat32) / double(W)).view({1, 1, W}).expand({1, H, W}).clone();
  std::mt19937_64 rng(5);
  for (int k = 0; k < 12; ++k) {  // invalid squares
    const int64_t y = int64_t(rng() % uint64_t(H - 6)), x = int64_t(rng() % uint64_t(W - 6));
    s.mask.narrow(1, y, 6).narrow(2, x, 6).zero_();
  }
  // Spectral pattern to check orientation later: value = column index.
  s.spectral = torch::arange(W, torch::kFloat32).view({1, 1, W}).expand({3, H, W}).clone() + 1000 * torch::arange(H, torch::kFloat32).view({1, H, 1});
  scenes[0].scene = s;
  scenes[1].scene = flat_scene(w, 10, 10, 0.5, 1.0);
  const data::PatchSampler sampler(scenes, S, 8, 2);
  CHECK(sampler.depth_bins_used() >= 6);
  const data::IlluminantBank bank({"D65", "A"}, w, 10e-9);
  const auto specs = sampler.draw(500, 42, bank.size(), 0.5, 1.0);
  double balanced = 0.0;
  for (const auto& p : specs) {
    REQUIRE(p.scene == 0);
    const data::Patch patch = sampler.extract(p, &bank);
    REQUIRE(patch.mask.min().item<float>() == 1.0f);
    REQUIRE(patch.spectral.sizes() == torch::IntArrayRef({3, S, S}));
    balanced += (1.0 / patch.depth_m).mean().item<double>() / double(specs.size());
  }
  // Depth coverage: positions drawn uniformly (by rejection) are mostly far on
  // this ramp (1/Z is convex in x); the sampler's depth bins draw near patches
  // as often as far ones, so its mean inverse depth is clearly higher.
  double uniform = 0.0;
  int64_t accepted = 0;
  while (accepted < 500) {
    const int64_t y = int64_t(rng() % uint64_t(H - S + 1)), x = int64_t(rng() % uint64_t(W - S + 1));
    if (s.mask[0].narrow(0, y, S).narrow(1, x, S).min().item<float>() < 1.0f) continue;
    uniform += (1.0 / s.depth_m[0].narrow(0, y, S).narrow(1, x, S)).mean().item<double>() / 500.0;
    ++accepted;
  }
  INFO("mean inverse depth: balanced " << balanced << ", uniform positions " << uniform);
  CHECK(balanced > uniform + 0.1);
  // Deterministic for a seed, different for another.
  const auto again = sampler.draw(500, 42, bank.size(), 0.5, 1.0);
  const auto other = sampler.draw(500, 43, bank.size(), 0.5, 1.0);
  bool same = true, differs = false;
  for (size_t i = 0; i < specs.size(); ++i) {
    same = same && specs[i].x == again[i].x && specs[i].y == again[i].y && specs[i].rot90 == again[i].rot90 &&
           specs[i].flip == again[i].flip && specs[i].lighting.illuminant == again[i].lighting.illuminant;
    differs = differs || specs[i].x != other[i].x || specs[i].y != other[i].y;
  }
  CHECK(same);
  CHECK(differs);
  // Flip then rotate: a flipped, once-rotated patch equals the same ops done by hand.
  data::PatchSpec p = specs[0];
  p.flip = true;
  p.rot90 = 1;
  p.lighting = {0, 1.0};
  const torch::Tensor got = sampler.extract(p, &bank).spectral[0];
  const torch::Tensor raw = s.spectral[0].narrow(0, p.y, S).narrow(1, p.x, S);
  const torch::Tensor manual = torch::rot90(raw.flip({1}), 1, {0, 1}) * bank.spectrum(0)[0];
  CHECK(got.equal(manual));
  // No valid window anywhere: refused.
  std::vector<data::LoadedScene> holes(1);
  holes[0].scene = flat_scene(w, 30, 30, 0.5, 1.0);
  holes[0].scene.mask.narrow(1, 15, 1).zero_();
  CHECK_THROWS_AS(data::PatchSampler(holes, 20), InputError);
}

TEST_CASE("data: the generator is deterministic, varied and in range", "[data][generator]") {
  const GeneratorConfig g = small_generator();
  const auto w = nm({450, 500, 550, 600, 650});
  const data::ReflectanceLibrary lib(w, 10e-9);
  const auto a = data::generate_tabletop_scene(g, lib, w, 7);
  const auto b = data::generate_tabletop_scene(g, lib, w, 7);
  CHECK(a.scene.spectral.equal(b.scene.spectral));
  CHECK(a.scene.depth_m.equal(b.scene.depth_m));
  CHECK(a.scene.mask.equal(b.scene.mask));
  CHECK(a.notes == b.notes);
  int varied = 0;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    const auto s = data::generate_tabletop_scene(g, lib, w, seed);
    INFO("seed " << seed << ": " << s.notes);
    const torch::Tensor valid = s.scene.mask[0] > 0.5;
    REQUIRE(valid.to(torch::kFloat32).mean().item<double>() > 0.3);  // no wall: the sky is invalid
    const torch::Tensor z = s.scene.depth_m[0].masked_select(valid);
    CHECK(z.min().item<double>() >= g.depth_min_m * 0.95);
    CHECK(z.max().item<double>() <= g.depth_max_m * 1.0001);
    CHECK(s.scene.spectral.min().item<double>() >= 0.0);
    CHECK(s.scene.spectral.max().item<double>() <= 1.0);
    // Several distinct spectra (shape, not just brightness) and depths.
    const torch::Tensor spec = s.scene.spectral.reshape({5, -1}).t();
    const torch::Tensor shape = spec / spec.sum(1, true).clamp_min(1e-6);
    const torch::Tensor q = (shape * 50).round();
    const auto uniq = std::get<0>(torch::unique_dim(q, 0));
    const bool many_spectra = uniq.size(0) >= 4;
    const bool deep = z.max().item<double>() / z.min().item<double>() > 1.5;
    if (many_spectra && deep) ++varied;
    CHECK_FALSE(s.scene.spectral.equal(a.scene.spectral));
  }
  CHECK(varied >= 5);
}

TEST_CASE("data: the ColorChecker scene holds the 24 patch spectra inside the layout boxes", "[data][generator]") {
  GeneratorConfig g = small_generator();
  g.width_px = 240;
  g.height_px = 180;
  g.colorchecker_depth_m = 0.8;
  const auto w = nm({450, 500, 550, 600, 650});
  const data::ReflectanceLibrary lib(w, 10e-9);
  std::vector<std::array<int64_t, 4>> boxes;
  const auto s = data::generate_colorchecker_scene(g, lib, w, &boxes);
  REQUIRE(boxes.size() == 24);
  for (size_t i = 0; i < 24; ++i) {
    const auto& b = boxes[i];
    REQUIRE(b[2] > b[0]);
    REQUIRE(b[3] > b[1]);
    const torch::Tensor region = s.scene.spectral.narrow(1, b[1], b[3] - b[1]).narrow(2, b[0], b[2] - b[0]);
    const torch::Tensor expect = lib.colorchecker()[int64_t(i)].to(torch::kFloat32).view({-1, 1, 1});
    CHECK((region - expect).abs().max().item<double>() < 1e-6);
    CHECK((s.scene.depth_m.narrow(1, b[1], b[3] - b[1]).narrow(2, b[0], b[2] - b[0]) - 0.8).abs().max().item<double>() < 1e-6);
  }
  CHECK(lib.patch_names().front() == "dark_skin");
  CHECK(lib.patch_names().back() == "black_2");
}

TEST_CASE("data: lifting sRGB to spectra reproduces the colour and stays in range", "[data]") {
  const auto w = nm({420, 440, 460, 480, 500, 520, 540, 560, 580, 600, 620, 640, 660});
  const data::ReflectanceLibrary lib(w, 20e-9);
  const torch::Tensor d65 = optics::illuminant_bands("D65", w, 20e-9);
  // The ColorChecker patches' own sRGB renderings, as a 4 × 6 image.
  const torch::Tensor cube = lib.colorchecker().t().reshape({int64_t(w.size()), 4, 6}).to(torch::kFloat32);
  const torch::Tensor rgb = data::spectral_to_linear_srgb(cube, w, 20e-9, d65);
  const torch::Tensor lifted = data::lift_srgb_to_reflectance(rgb, lib, w, 20e-9);
  CHECK(lifted.min().item<double>() >= 0.0);
  CHECK(lifted.max().item<double>() <= 1.0);
  const torch::Tensor back = data::spectral_to_linear_srgb(lifted, w, 20e-9, d65);
  // Patches whose lifted spectrum needed no clipping reproduce their colour.
  const torch::Tensor unclipped = ((lifted > 0) & (lifted < 1)).all(0);
  const torch::Tensor err = (back - rgb).abs().amax(0).masked_select(unclipped);
  REQUIRE(err.numel() >= 12);
  CHECK(err.max().item<double>() < 1e-4);
  // Grey stays flat-ish: white's lifted spectrum varies little over the bands.
  const torch::Tensor white = data::lift_srgb_to_reflectance(torch::ones({3, 1, 1}), lib, w, 20e-9).flatten();
  CHECK((white.max() - white.min()).item<double>() < 0.25);
}

TEST_CASE("data: ensure_dataset generates on first use only when the config allows it", "[data][generator]") {
  const fs::path root = fs::temp_directory_path() / "hsd_test_ensure";
  fs::remove_all(root);
  const std::vector<std::string> small{"data.root=\"" + root.string() + "\"", "data.generator.train_scenes=1",
                                       "data.generator.val_scenes=0", "data.generator.test_scenes=0",
                                       "data.generator.colorchecker=false", "data.generator.width_px=40",
                                       "data.generator.height_px=32"};
  auto with = [&](const std::string& extra) {
    auto o = small;
    o.push_back(extra);
    return load_config(test::source_path("configs/tiny.json"), o);
  };
  try {
    data::ensure_dataset(with("data.generate_if_missing=false"));
    FAIL("no error");
  } catch (const InputError& e) {
    CHECK_THAT(e.what(), Catch::Contains("data.root"));
  }
  CHECK_FALSE(fs::exists(root / "manifest.json"));
  CHECK(data::ensure_dataset(with("data.generate_if_missing=true")) == root.string());
  const data::Manifest m = data::read_manifest(root.string());
  REQUIRE(m.scenes.size() == 1);
  CHECK(m.scenes[0].split == "train");
  const auto loaded = data::load_split(root.string(), "train", with("seed=0").optics.wavelengths_m(), 100e-9, 1);
  CHECK(loaded[0].scene.spectral.sizes() == torch::IntArrayRef({3, 32, 40}));
  // The same settings again, or only another seed (runs of several seeds share
  // one dataset): the folder is used as it is (nothing rewritten).
  const auto t0 = fs::last_write_time(root / "manifest.json");
  const int w0 = log::warning_count();
  data::ensure_dataset(with("data.generate_if_missing=true"));
  data::ensure_dataset(with("seed=7"));
  CHECK(fs::last_write_time(root / "manifest.json") == t0);
  CHECK(log::warning_count() == w0);
  // Other generator settings: the generator's own folder is made again, with a warning.
  data::ensure_dataset(with("data.generator.layouts={\"dead_leaves\":1,\"tabletop\":0,\"classic_tabletop\":0}"));
  CHECK(log::warning_count() == w0 + 1);
  CHECK_THAT(data::read_manifest(root.string()).scenes[0].notes, Catch::StartsWith("dead leaves"));
  // What hsd_scenes wrote is the user's output: other settings give a warning, never a replacement.
  const fs::path mine = fs::temp_directory_path() / "hsd_test_ensure_scenes";
  fs::remove_all(mine);
  auto at_mine = [&](const std::string& extra) {
    auto o = small;
    o.push_back("data.root=\"" + mine.string() + "\"");
    o.push_back(extra);
    return load_config(test::source_path("configs/tiny.json"), o);
  };
  data::generate_dataset(at_mine("seed=0"), mine.string());  // as hsd_scenes does
  const auto t1 = fs::last_write_time(mine / "manifest.json");
  data::ensure_dataset(at_mine("data.generator.texture_scale_max=1.0"));
  CHECK(log::warning_count() == w0 + 2);
  CHECK(fs::last_write_time(mine / "manifest.json") == t1);
  // A garbled generator.json: a warning, nothing replaced.
  std::ofstream(root / "generator.json") << "[1, 2";
  const auto t2 = fs::last_write_time(root / "manifest.json");
  data::ensure_dataset(with("data.generator.texture_scale_max=1.1"));
  CHECK(log::warning_count() == w0 + 3);
  CHECK(fs::last_write_time(root / "manifest.json") == t2);
  // An earlier hsd's generated folder (colorchecker_layout.json, no generator.json): a warning, nothing replaced.
  fs::remove(root / "generator.json");
  std::ofstream(root / "colorchecker_layout.json") << "{}";
  data::ensure_dataset(with("data.generator.texture_scale_max=1.2"));
  CHECK(log::warning_count() == w0 + 4);
  CHECK(fs::last_write_time(root / "manifest.json") == t2);
  // A dataset the generator did not write is never replaced, and nothing is said.
  fs::remove(root / "colorchecker_layout.json");
  data::ensure_dataset(with("data.generator.texture_scale_max=1.2"));
  CHECK(log::warning_count() == w0 + 4);
  CHECK(fs::last_write_time(root / "manifest.json") == t2);
  CHECK_THAT(data::read_manifest(root.string()).scenes[0].notes, Catch::StartsWith("dead leaves"));
}
