// The apps as a user runs them: exit codes, one-line errors, the contract's
// output files, and no partial files.
#include <catch2/catch.hpp>
#include <cmath>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "common/tensor_io.h"
#include "data/image_io.h"
#include "data/scene_exr.h"
#include "optics/spectrum.h"
#include "helpers.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {
using test::capture;
using test::Run;
using test::run;
int lines(const std::string& s) { return int(std::count(s.begin(), s.end(), '\n')); }

// `hsd_bench ARGS --json` run from the source folder: exit 0 and exactly one JSON object on stdout.
nlohmann::json bench_json(const std::string& args) {
  const auto [out, code] = capture("cd " + std::string(HSD_SOURCE_DIR) + " && " + std::string(HSD_BIN_DIR) +
                                   "/hsd_bench " + args + " --json 2>/dev/null");
  CHECK(code == 0);
  INFO("stdout: " << out);
  REQUIRE(lines(out) == 1);
  return nlohmann::json::parse(out);
}
}  // namespace

TEST_CASE("hsd_psf writes the contract's psf.pt and atlas and config", "[app]") {
  const fs::path out = fs::temp_directory_path() / "hsd_test_psf_out";
  fs::remove_all(out);
  const Run r = run("hsd_psf --config configs/tiny.json --set optics.doe.init=spiral --out " + out.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  CHECK(fs::exists(out / "psf_atlas.png"));
  CHECK(fs::exists(out / "config.json"));
  const TensorDict d = load_tensor_dict((out / "psf.pt").string());
  const torch::Tensor psf = d.at("psf");
  CHECK(psf.scalar_type() == torch::kFloat32);
  CHECK(psf.sizes() == torch::IntArrayRef({3, 2, 15, 15}));
  CHECK((psf.sum({2, 3}) - 1.0).abs().max().item<double>() < 1e-5);
  CHECK(d.at("energy_in_window").sizes() == torch::IntArrayRef({3, 2}));
  CHECK(d.at("wavelengths_m").scalar_type() == torch::kFloat64);
  CHECK(d.at("wavelengths_m")[1].item<double>() == Approx(550e-9));
  CHECK(d.at("depths_m").sizes() == torch::IntArrayRef({2}));
  CHECK(d.at("height_map_m").sizes() == torch::IntArrayRef({64, 64}));
  CHECK(d.at("camera_response").sizes() == torch::IntArrayRef({3, 3}));
  CHECK(d.at("refractive_index").sizes() == torch::IntArrayRef({3}));
  for (const char* k : {"pixel_pitch_m", "sensor_distance_m", "aperture_diameter_m", "doe_pitch_m"}) {
    CHECK(d.at(k).scalar_type() == torch::kFloat64);
    CHECK(d.at(k).dim() == 0);
  }
  for (const auto& e : fs::directory_iterator(out)) CHECK(e.path().string().find(".tmp") == std::string::npos);

  // Python reads it with torch.load (python3-torch from Debian, installed by scripts/setup.sh).
  const std::string py = "/usr/bin/python3 -c \"import torch; d = torch.load('" + (out / "psf.pt").string() +
                         "'); p = d['psf']; assert tuple(p.shape) == (3, 2, 15, 15), p.shape; "
                         "assert abs(float(p.sum((2, 3)).min()) - 1) < 1e-5; "
                         "assert d['wavelengths_m'].dtype == torch.float64; print('ok')\" 2>&1";
  const std::string got = capture(py).first;
  INFO("python3 said: " << got << " (needs python3-torch: bash scripts/setup.sh)");
  CHECK(got.find("ok") != std::string::npos);
}

TEST_CASE("bad input is exit 2 with one line naming the key or file", "[app]") {
  const std::string out = (fs::temp_directory_path() / "hsd_test_bad_out").string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--config configs/tiny.json --set optics.psf_size=4 --out " + out, "optics.psf_size"},
      {"--config configs/tiny.json --set optics.colour=1 --out " + out, "optics.colour"},
      {"--config nonexistent.json --out " + out, "nonexistent.json"},
      {"--config configs/tiny.json", "--out"},
      {"--config configs/tiny.json --bogus --out " + out, "--bogus"},
      {"--config configs/tiny.json --set optics.doe.init=file:/nonexistent.pt --out " + out, "/nonexistent.pt"},
      {"--config configs/tiny.json --set optics.doe.init=fisher --set optics.doe.fisher_path=/none.pt --out " + out,
       "hsd_fisher"},
  };
  for (const auto& [args, names] : cases) {
    const Run r = run("hsd_psf " + args);
    INFO("hsd_psf " << args << "\nstderr: " << r.err);
    CHECK(r.code == 2);
    CHECK_THAT(r.err, Catch::Contains(names));
    CHECK(lines(r.err) == 1);
  }
  CHECK(run("hsd_psf --help").code == 0);
}

TEST_CASE("hsd_bench psf --json prints exactly one JSON object on stdout", "[app][bench]") {
  const auto j = bench_json("psf --config configs/tiny.json --repeats 1");
  REQUIRE(j.is_object());
  for (const char* k : {"threads", "seconds_fwd", "seconds_fwd_bwd", "peak_rss_mib", "psf_rel_l1_max", "psf_rel_l1_mean"})
    CHECK(j.contains(k));
  CHECK(j["bands"] == 3);
  CHECK(j["psf_rel_l1_max"].get<double>() < 0.03);
  CHECK(j["baseline_fft_bilinear"]["psf_rel_l1_max"].get<double>() > j["psf_rel_l1_max"].get<double>());
  CHECK(run("hsd_bench nosuch").code == 2);
}

TEST_CASE("hsd_simulate renders a scene: contract files and a white scene gives the expected colour", "[app][simulate]") {
  const fs::path dir = fs::temp_directory_path() / "hsd_test_simulate";
  fs::remove_all(dir);
  fs::create_directories(dir);
  // tiny.json bands (450, 550, 650 nm); grey reflectance 0.5, two depths.
  data::SpectralScene s;
  s.wavelengths_m = {450e-9, 550e-9, 650e-9};
  s.spectral = torch::full({3, 24, 30}, 0.5);
  s.depth_m = torch::full({1, 24, 30}, 0.5);
  s.depth_m.narrow(2, 15, 15).fill_(1.5);
  s.mask = torch::ones({1, 24, 30});
  const std::string scene = (dir / "grey.exr").string();
  data::write_scene_exr(scene, s);
  const std::string out = (dir / "out").string();
  const Run r = run("hsd_simulate --config configs/tiny.json --scene " + scene + " --out " + out);
  INFO(r.err);
  REQUIRE(r.code == 0);
  CHECK(fs::exists(fs::path(out) / "sensor.png"));
  CHECK(fs::exists(fs::path(out) / "psf_atlas.png"));
  CHECK(fs::exists(fs::path(out) / "config.json"));
  const torch::Tensor J = data::read_channels_exr(out + "/sensor.exr", {"R", "G", "B"});
  REQUIRE(J.sizes() == torch::IntArrayRef({3, 24, 30}));
  // A uniform grey scene stays uniform: J_c = 0.5 Σ_λ Ω_c,λ E_λ (PSFs and masks sum to 1).
  const torch::Tensor omega = optics::camera_response("canon_5d_mark_iii", s.wavelengths_m, 100e-9);
  const torch::Tensor e = optics::illuminant_bands("D65", s.wavelengths_m, 100e-9);
  const torch::Tensor expected = 0.5 * (omega * e.view({1, -1})).sum(1);
  for (int64_t c = 0; c < 3; ++c) CHECK((J[c] - expected[c]).abs().max().item<double>() < 1e-5);
  CHECK_THAT(r.err, Catch::Contains("2 of 2"));
}

TEST_CASE("hsd_simulate refuses bad scenes with exit 2 naming the file", "[app][simulate]") {
  const fs::path dir = fs::temp_directory_path() / "hsd_test_simulate_bad";
  fs::create_directories(dir);
  data::SpectralScene s;
  s.wavelengths_m = {450e-9, 500e-9};  // tiny.json has 3 bands
  s.spectral = torch::full({2, 8, 8}, 0.5);
  s.depth_m = torch::full({1, 8, 8}, 1.0);
  const std::string scene = (dir / "two_bands.exr").string();
  data::write_scene_exr(scene, s);
  const std::string out = (dir / "out").string();
  Run r = run("hsd_simulate --config configs/tiny.json --scene " + scene + " --out " + out);
  CHECK(r.code == 2);
  CHECK_THAT(r.err, Catch::Contains("two_bands.exr") && Catch::Contains("optics.wavelengths_nm"));
  CHECK(lines(r.err) == 1);
  r = run("hsd_simulate --config configs/tiny.json --scene " + (dir / "none.exr").string() + " --out " + out);
  CHECK(r.code == 2);
  CHECK_THAT(r.err, Catch::Contains("none.exr"));
  r = run("hsd_simulate --config configs/tiny.json --out " + out);
  CHECK(r.code == 2);
  CHECK_THAT(r.err, Catch::Contains("--scene"));
  CHECK_FALSE(fs::exists(fs::path(out) / "sensor.exr"));
}

TEST_CASE("hsd_bench data and train --json measure the data path and a training step", "[app][bench][data]") {
  const auto j = bench_json("data --config configs/tiny.json --scenes 2 --threads 2"
                            " --set data.generator.width_px=64 --set data.generator.height_px=48"
                            " --set data.patch_size_px=16 --patches 100");
  for (const char* k : {"seconds_generate_per_scene", "seconds_load_1_thread", "seconds_load_n_threads",
                        "seconds_draw_patches", "seconds_extract_per_patch", "sampler_candidates", "threads"})
    CHECK(j.contains(k));
  CHECK(j["sampler_candidates"].get<int64_t>() > 0);
  CHECK(run("hsd_bench data --scenes 0").code == 2);
  const auto t = bench_json("train --profile --config configs/tiny.json --patch 16 --repeats 1 --threads 2"
                            " --set model.base_width=4 --set model.levels=2");
  CHECK(t["seconds_per_step"].get<double>() > 0.0);
  CHECK(t["seconds_per_step_float32"].get<double>() > 0.0);
  CHECK(t["seconds_per_step_bfloat16"].get<double>() > 0.0);
  CHECK(t.contains("peak_rss_mib"));
  // --profile: every phase timed; the phases are disjoint intervals of the profiled steps, so their sum cannot
  // exceed those steps' own wall time (compared with the same steps, not with the separately timed ones, which
  // another process on the machine can make faster or slower).
  REQUIRE(t.contains("profile_seconds"));
  REQUIRE(t.contains("profile_step_wall_seconds"));
  double sum = 0;
  for (const char* k : {"PSF forward", "sensor image forward", "network forward", "network backward",
                        "sensor image backward", "PSF backward", "gradient checks, clipping, Adam"}) {
    INFO(k);
    CHECK(t["profile_seconds"][k].get<double>() > 0.0);
    sum += t["profile_seconds"][k].get<double>();
  }
  // the network's linear inputs: a phase of its own (next to nothing without them, as in tiny.json)
  const double inputs = t["profile_seconds"]["network inputs forward (pre-inversion, spectral Wiener)"].get<double>();
  CHECK(inputs >= 0.0);
  sum += inputs;
  CHECK(sum <= t["profile_step_wall_seconds"].get<double>() * 1.001 + 1e-4);
  CHECK(sum > 0.5 * t["profile_step_wall_seconds"].get<double>());  // the phases cover most of the step
  CHECK(run("hsd_bench train --batch 0").code == 2);
  const auto r = bench_json("reconstruct --config configs/tiny.json --size 64 --tile 32 --overlap 0"
                            " --threads 2 --set model.base_width=4 --set model.levels=2");
  CHECK(r["seconds_per_megapixel"].get<double>() > 0.0);
}

TEST_CASE("hsd_bench apps times whole processes: the launcher's help and hsd_simulate on one and all layers", "[app][bench]") {
  const auto j = bench_json("apps --config configs/tiny.json --size 48 --repeats 1 --threads 2");
  CHECK(j["seconds_psf_help"].get<double>() > 0.0);
  CHECK(j["seconds_simulate_one_layer"].get<double>() > 0.0);
  CHECK(j["seconds_simulate_all_layers"].get<double>() > 0.0);
  CHECK(j["layers"].get<int64_t>() == 2);
}

TEST_CASE("the launchers print the usage without the app and start the app with the OpenMP wait policy", "[app]") {
  for (const std::string app : {"hsd_psf", "hsd_simulate", "hsd_train", "hsd_eval", "hsd_bench", "hsd_curves"}) {
    INFO(app);
    const auto [out, code] = capture(std::string(HSD_BIN_DIR) + "/" + app + " --help 2>&1");
    CHECK(code == 0);
    CHECK_THAT(out, Catch::StartsWith(app + " "));
    // The same text as the app's own (libexec), which parses its flags first.
    const auto [own, own_code] = capture(std::string(HSD_BIN_DIR) + "/../libexec/" + app + " --help 2>&1");
    CHECK(own_code == 0);
    CHECK(own == out);
  }
  // Anything but a lone --help reaches the app, whose parser answers.
  const Run r = run("hsd_psf --help --bogus");
  CHECK(r.code == 2);
  CHECK_THAT(r.err, Catch::Contains("--bogus"));
}

TEST_CASE("the launchers set OpenBLAS's short idle polling for training only and keep the caller's value", "[app]") {
  // Each launcher beside a stand-in app (a script printing what it was given).
  const fs::path d = fs::temp_directory_path() / "hsd_test_launcher_env";
  fs::remove_all(d);
  fs::create_directories(d / "bin");
  fs::create_directories(d / "libexec");
  for (const std::string app : {"hsd_train", "hsd_ablate", "hsd_bench", "hsd_simulate", "hsd_eval"}) {
    fs::copy_file(fs::path(HSD_BIN_DIR) / app, d / "bin" / app);
    std::ofstream(d / "libexec" / app) << "#!/bin/sh\necho \"$OPENBLAS_THREAD_TIMEOUT|$OMP_WAIT_POLICY|$1\"\n";
    fs::permissions(d / "libexec" / app, fs::perms::owner_all);
  }
  const auto env_of = [&](const std::string& cmd) {
    const auto [out, code] = capture("env -u OPENBLAS_THREAD_TIMEOUT -u OMP_WAIT_POLICY " + cmd + " 2>&1");
    CHECK(code == 0);
    return out;
  };
  const std::string bin = (d / "bin").string() + "/";
  CHECK(env_of(bin + "hsd_train --config x") == "4|PASSIVE|--config\n");
  CHECK(env_of(bin + "hsd_ablate --config x") == "4|PASSIVE|--config\n");
  CHECK(env_of(bin + "hsd_bench train") == "4|PASSIVE|train\n");
  CHECK(env_of(bin + "hsd_bench sim") == "|PASSIVE|sim\n");
  CHECK(env_of(bin + "hsd_simulate --config x") == "|PASSIVE|--config\n");
  CHECK(env_of(bin + "hsd_eval --config x") == "|PASSIVE|--config\n");
  CHECK(env_of("OPENBLAS_THREAD_TIMEOUT=20 OMP_WAIT_POLICY=ACTIVE " + bin + "hsd_train --config x") ==
        "20|ACTIVE|--config\n");
  fs::remove_all(d);
}

TEST_CASE("hsd_curves compares runs' metrics in one plot per column with a table of last values", "[app]") {
  const fs::path d = fs::temp_directory_path() / "hsd_test_curves";
  fs::remove_all(d);
  for (const auto& [name, last] : std::vector<std::pair<std::string, std::string>>{{"a", "0.5"}, {"b", "0.51"}}) {
    fs::create_directories(d / name);
    std::ofstream(d / name / "metrics.csv") << "step,wall_s,train_loss,val_loss\n0,0,,0.9\n5,1,0.7,\n10,2,0.6," << last << "\n";
  }
  const std::string runs = " --runs " + (d / "a").string() + "," + (d / "b").string();
  const auto [out, code] = capture(std::string(HSD_BIN_DIR) + "/hsd_curves" + runs + " --columns val_loss --out " +
                                   (d / "cmp").string() + " 2>/dev/null");
  CHECK(code == 0);
  CHECK_THAT(out, Catch::Contains("| b | 0.51 (+2.00%) |"));
  CHECK(fs::exists(d / "cmp" / "curves.png"));
  CHECK(fs::exists(d / "cmp" / "val_loss.png"));
  CHECK(fs::exists(d / "cmp" / "curves.md"));
  const Run bad = run("hsd_curves" + runs + " --columns val_nothing --out " + (d / "cmp2").string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("val_nothing"));
  CHECK(run("hsd_curves --runs " + (d / "none").string() + " --out " + (d / "cmp3").string()).code == 2);
  fs::remove_all(d);
}

TEST_CASE("hsd_bench sim --json reports the contract's keys", "[app][bench]") {
  const auto j = bench_json("sim --patch 32 --bands 3 --depths 3 --psf 9 --pupil 64 --repeats 1 --threads 2");
  for (const char* k : {"seconds_fwd_bwd", "peak_rss_mib", "seconds_floor", "baseline_seconds_fwd_bwd", "patch", "bands",
                        "depths", "psf", "pupil", "threads", "seconds_fwd_bwd_one_layer"})
    CHECK(j.contains(k));
  CHECK(j["patch"] == 32);
  CHECK(j["pupil"] == 64);
  CHECK(j["threads"] == 2);
  CHECK(run("hsd_bench sim --psf 8").code == 2);
}

TEST_CASE("hsd_bench accuracy writes the error-vs-runtime table, plot, leave-out table and summary", "[app][bench]") {
  const fs::path dir = fs::temp_directory_path() / "hsd_test_accuracy";
  fs::remove_all(dir);
  const Run r = run("hsd_bench accuracy --config configs/tiny.json --patch 32 --repeats 1 --threads 2 --ref-oversampling 2 "
                    "--out " + dir.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  std::ifstream csv(dir / "error_vs_runtime.csv");
  std::string header, line;
  std::getline(csv, header);
  for (const char* k : {"name", "seconds", "psf_rel_l1_max", "psf_rel_l1_mean", "sensor_psnr_db"})
    CHECK(header.find(k) != std::string::npos);
  std::map<std::string, double> err;  // name -> psf_rel_l1_max (6th column)
  while (std::getline(csv, line)) {
    std::vector<std::string> f;
    std::string cell;
    bool quoted = false;
    for (char ch : line) {
      if (ch == '"') quoted = !quoted;
      else if (ch == ',' && !quoted) f.push_back(cell), cell.clear();
      else cell += ch;
    }
    f.push_back(cell);
    REQUIRE(f.size() >= 6);
    err[f[0]] = std::stod(f[5]);
    CHECK(std::isfinite(std::stod(f[3])));
  }
  REQUIRE(err.count("default"));
  CHECK(err.size() >= 15);
  for (const auto& [name, e] : err) CHECK(std::isfinite(e));
  // A finer pupil moves toward the reference; point-sampled pixels and the FFT method away from it.
  CHECK(err["pupil_x2"] < err["default"]);
  CHECK(err["spectral_3_pupil_x2"] < err["default"]);
  CHECK(err["nodes_1"] > err["default"]);
  CHECK(err["fft_bilinear"] > err["exact_mft"]);
  CHECK(std::fabs(err["rank_tol_1e-08"] - err["exact_mft"]) < 1e-6);
  CHECK(fs::file_size(dir / "error_vs_runtime.png") > 1000);
  CHECK(fs::exists(dir / "leave_out.csv"));
  std::ifstream md(dir / "accuracy.md");
  const std::string text((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  CHECK(text.find("Pareto") != std::string::npos);
  CHECK(text.find("Recommendations") != std::string::npos);
  CHECK(run("hsd_bench accuracy --config configs/tiny.json").code == 2);  // --out missing
}

TEST_CASE("hsd_scenes writes a deterministic dataset with manifest, previews and the ColorChecker", "[app][data]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_scenes";
  fs::remove_all(base);
  const std::string sets =
      " --set data.generator.train_scenes=2 --set data.generator.val_scenes=1 --set data.generator.test_scenes=1"
      " --set data.generator.width_px=64 --set data.generator.height_px=48";
  for (const char* d : {"a", "b"}) {
    const Run r = run("hsd_scenes --config configs/tiny.json" + sets + " --out " + (base / d).string());
    INFO(r.err);
    REQUIRE(r.code == 0);
  }
  const fs::path a = base / "a";
  const auto m = nlohmann::json::parse(std::ifstream(a / "manifest.json"));
  REQUIRE(m["scenes"].size() == 5);
  std::map<std::string, int> splits;
  for (const auto& s : m["scenes"]) {
    splits[s["split"].get<std::string>()]++;
    const std::string stem = fs::path(s["file"].get<std::string>()).stem().string();
    CHECK(fs::exists(a / (stem + "_srgb.png")));
    CHECK(fs::exists(a / (stem + "_depth.png")));
    CHECK_FALSE(s["notes"].get<std::string>().empty());
    // Same seed, same scenes.
    const data::SpectralScene x = data::read_scene_exr((a / s["file"].get<std::string>()).string());
    const data::SpectralScene y = data::read_scene_exr((base / "b" / s["file"].get<std::string>()).string());
    CHECK(x.spectral.equal(y.spectral));
    CHECK(x.depth_m.equal(y.depth_m));
    CHECK(x.wavelengths_m.size() == 3);
  }
  CHECK(splits["train"] == 2);
  CHECK(splits["val"] == 1);
  CHECK(splits["test"] == 2);  // one generated, plus the ColorChecker (never train)
  CHECK(m["scenes"][4]["file"] == "colorchecker.exr");
  CHECK(m["scenes"][4]["split"] == "test");
  const auto layout = nlohmann::json::parse(std::ifstream(a / "colorchecker_layout.json"));
  CHECK(layout["patches"].size() == 24);
  CHECK(fs::exists(a / "config.json"));
  // The realism statistics: per generated scene (not the ColorChecker), their mean, the CAVE reference, the targets.
  const auto realism = nlohmann::json::parse(std::ifstream(a / "realism.json"));
  CHECK(realism["scenes"].size() == 4);
  for (const char* k : {"textured_fraction", "psd_slope", "pcs_99", "rgb_unexplained", "inv_depth_hist", "inv_depth_quarters"})
    CHECK(realism["mean"].contains(k));
  // 3 bands: RGB explains them exactly, so the CAVE reference's residual is 0 here (0.048 on the paper's 25).
  CHECK(realism["reference"]["rgb_unexplained"].get<double>() == Approx(0.0).margin(1e-6));
  CHECK(realism["targets"].size() == 4);
  CHECK(fs::exists(a / "realism.md"));
  // A different seed gives different scenes.
  const Run r = run("hsd_scenes --config configs/tiny.json" + sets + " --set seed=9 --out " + (base / "c").string());
  REQUIRE(r.code == 0);
  CHECK_FALSE(data::read_scene_exr((a / "scene_train_000.exr").string())
                  .spectral.equal(data::read_scene_exr((base / "c" / "scene_train_000.exr").string()).spectral));
  // Bad generator keys: exit 2, one line naming the key, nothing written.
  for (const auto& [set, key] : std::vector<std::pair<std::string, std::string>>{
           {"data.generator.width_px=4", "data.generator.width_px"},
           {"data.generator.depth_max_m=0.3", "data.generator.depth_max_m"},
           {"data.generator.colour=1", "data.generator.colour"},
           {"data.illuminants=[\"D65\",3]", "data.illuminants"},
           {"'data.generator.layouts={\"forest\":1}'", "data.generator.layouts.forest"},
           {"'data.generator.layouts={\"tabletop\":0}'", "data.generator.layouts"},
           {"data.generator.texture_dir=/nonexistent_hsd", "data.generator.texture_dir"}}) {
    const Run bad = run("hsd_scenes --config configs/tiny.json --set " + set + " --out " + (base / "bad").string());
    CHECK(bad.code == 2);
    CHECK_THAT(bad.err, Catch::Contains(key));
    CHECK(lines(bad.err) == 1);
  }
  CHECK_FALSE(fs::exists(base / "bad"));
}

TEST_CASE("hsd_import turns the real Middlebury Aloe picture into a valid scene", "[app][data]") {
  const fs::path out = fs::temp_directory_path() / "hsd_test_import";
  fs::remove_all(out);
  const std::string real = "data/real/middlebury2006_aloe/";
  const Run r = run("hsd_import --config configs/tiny.json --rgb " + real + "aloeL.jpg --disparity " + real +
                    "aloeGT.png --scale 0.1 --name aloe --out " + out.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  const data::SpectralScene s = data::read_scene_exr((out / "aloe.exr").string());
  CHECK(s.spectral.size(1) == 111);
  CHECK(s.spectral.size(2) == 128);
  const torch::Tensor valid = s.mask[0] > 0.5;
  const double frac = valid.to(torch::kFloat64).mean().item<double>();
  CHECK(frac > 0.9);   // 3.5 % of the disparities are unknown
  CHECK(frac < 1.0);
  const torch::Tensor z = s.depth_m[0].masked_select(valid);
  CHECK(z.min().item<double>() == Approx(0.4).epsilon(1e-3));  // tiny.json inherits the generator's 0.4-2.5 m
  CHECK(z.max().item<double>() == Approx(2.5).epsilon(1e-3));
  CHECK(s.spectral.min().item<double>() >= 0.0);
  CHECK(s.spectral.max().item<double>() <= 1.0);
  const auto m = nlohmann::json::parse(std::ifstream(out / "manifest.json"));
  REQUIRE(m["scenes"].size() == 1);
  CHECK_THAT(m["scenes"][0]["notes"].get<std::string>(), Catch::Contains("lifted"));
  // Bad inputs: exit 2 naming the file or flag.
  Run bad = run("hsd_import --config configs/tiny.json --rgb " + real + "none.jpg --disparity " + real + "aloeGT.png --out " + out.string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("none.jpg"));
  bad = run("hsd_import --config configs/tiny.json --rgb " + real + "aloeL.jpg --disparity " + real + "aloeL.jpg --out " + out.string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("single-channel"));
  bad = run("hsd_import --config configs/tiny.json --rgb " + real + "aloeL.jpg --disparity " + real + "aloeGT.png --scale 2 --out " + out.string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("--scale"));
}

namespace {
// Columns of metrics.csv: step -> (train_loss, val_loss).
std::map<std::string, std::pair<std::string, std::string>> loss_curve(const fs::path& csv) {
  std::map<std::string, std::pair<std::string, std::string>> out;
  const train::CsvTable t = train::read_csv_table(csv.string());
  for (size_t r = 0; r < t.rows.size(); ++r) out[t.cell(r, "step")] = {t.cell(r, "train_loss"), t.cell(r, "val_loss")};
  return out;
}
}  // namespace

TEST_CASE("hsd_train writes the contract's outputs and resumes exactly after SIGKILL", "[app][train]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_train_app";
  fs::remove_all(base);
  const std::string cfg =
      "hsd_train --config configs/tiny.json --set data.root=" + (base / "data").string() +
      " --set model.base_width=4 --set model.levels=2 --set train.batch_size=2 --set train.steps=24"
      " --set train.warmup_steps=0 --set train.decay=none --set train.val_patches=2 --set train.val_every=8"
      " --set train.log_every=1 --set train.checkpoint_every=2 --set data.patch_size_px=16"
      " --set data.generator.train_scenes=2 --set data.generator.val_scenes=1 --set data.generator.test_scenes=0"
      " --set data.generator.colorchecker=false --set data.generator.width_px=40 --set data.generator.height_px=32";
  const Run a = run(cfg + " --out " + (base / "a").string());
  INFO(a.err);
  REQUIRE(a.code == 0);
  for (const char* f : {"metrics.csv", "curves.png", "val_psnr.png", "val_depth.png", "config.json", "checkpoints/last.pt",
                        "val/step_000008_reconstructions.png", "val/step_000024_psf_atlas.png"})
    CHECK(fs::exists(base / "a" / f));
  std::ifstream hdr(base / "a" / "metrics.csv");
  std::string header;
  std::getline(hdr, header);
  for (const char* k : {"step", "wall_s", "train_loss", "val_loss", "val_baseline_hs_psnr_db", "val_baseline_depth_rmse_m",
                        "val_depth_saturated"})
    CHECK_THAT(header, Catch::Contains(k));
  CHECK_THAT(a.err, Catch::Contains("constant depth"));  // validation logs the baselines
  const auto curve_a = loss_curve(base / "a" / "metrics.csv");
  CHECK(curve_a.size() == 25);  // step 0 (validation only) and 1..24
  // Kill -9 as soon as a checkpoint exists, then resume: the same curve.
  const std::string b = (base / "b").string();
  const std::string kill = "cd " + std::string(HSD_SOURCE_DIR) + " && (" + std::string(HSD_BIN_DIR) + "/" + cfg +
                           " --out " + b + " > /dev/null 2>&1 & pid=$!; while [ ! -f " + b +
                           "/checkpoints/last.pt ]; do sleep 0.02; done; kill -9 $pid; wait $pid; exit 0)";
  REQUIRE(std::system(kill.c_str()) == 0);
  const Run r = run(cfg + " --out " + b + " --resume");
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto curve_b = loss_curve(base / "b" / "metrics.csv");
  CHECK(curve_b == curve_a);
  // The checkpoint is a torch pickle that also serves as a height-map file.
  const std::string py = "/usr/bin/python3 -c \"import torch; d = torch.load('" + (base / "a/checkpoints/last.pt").string() +
                         "'); assert int(d['step']) == 24; assert d['height_map_m'].dim() == 2; "
                         "assert d['doe_pitch_m'].dtype == torch.float64; print('ok')\" 2>&1";
  CHECK(capture(py).first.find("ok") != std::string::npos);
  // --resume without a checkpoint, and a bad key: exit 2 with one line.
  Run bad = run(cfg + " --out " + (base / "none").string() + " --resume");
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("last.pt"));
  bad = run(cfg + " --set train.lr_net=-1 --out " + (base / "c").string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("train.lr_net"));
  CHECK(lines(bad.err) == 1);
}

TEST_CASE("hsd_fisher writes the CRLB table and a design that training and hsd_psf can load", "[app][fisher]") {
  const fs::path out = fs::temp_directory_path() / "hsd_test_fisher";
  fs::remove_all(out);
  const std::string sets = " --set fisher.design_samples=32 --set fisher.window_px=9 --set fisher.steps=6"
                           " --set fisher.zernike_modes=6 --set fisher.photons=2000";
  const Run r = run("hsd_fisher --config configs/tiny.json" + sets + " --out " + out.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  for (const char* f : {"crlb.json", "crlb.md", "fisher_height.pt", "fisher_curve.png", "psf_atlas_fisher.png", "config.json"})
    CHECK(fs::exists(out / f));
  const auto j = nlohmann::json::parse(std::ifstream(out / "crlb.json"));
  for (const char* k : {"fresnel", "spiral", "fisher"}) {
    REQUIRE(j.contains(k));
    CHECK(j[k]["aggregate"].get<double>() > 0.0);
  }
  CHECK(j["fisher"]["aggregate"].get<double>() <= j["fresnel"]["aggregate"].get<double>());
  // The nuisance set used, the three aggregates, per-point condition numbers, and the same without nuisance parameters.
  CHECK(j["nuisance"] == nlohmann::json({"x", "y", "N"}));
  for (const char* k : {"fresnel", "spiral", "fisher"}) {
    for (const char* a : {"aggregate_capped_mean", "aggregate_median", "aggregate_mean", "condition_number"}) CHECK(j[k].contains(a));
    CHECK(j[k]["aggregate"] == j[k]["aggregate_capped_mean"]);
    REQUIRE(j[k].contains("without_nuisance"));
    // Unknown position and brightness never make a bound smaller.
    CHECK(j[k]["aggregate_mean"].get<double>() >= j[k]["without_nuisance"]["aggregate_mean"].get<double>() * (1 - 1e-9));
  }
  // The design is a height-map file for optics.doe.init = "fisher".
  const Run psf = run("hsd_psf --config configs/tiny.json --set optics.doe.init=fisher --set optics.doe.fisher_path=" +
                      (out / "fisher_height.pt").string() + " --out " + (out / "psf").string());
  INFO(psf.err);
  CHECK(psf.code == 0);
  for (const auto& [set, key] : std::vector<std::pair<std::string, std::string>>{
           {"fisher.basis=pixels", "fisher.basis"},
           {"'fisher.nuisance=[\"x\",\"z\"]'", "fisher.nuisance"},
           {"'fisher.nuisance=[\"x\",\"x\"]'", "fisher.nuisance"},
           {"fisher.aggregate=max", "fisher.aggregate"},
           {"fisher.aggregate_cap=0", "fisher.aggregate_cap"}}) {
    const Run bad = run("hsd_fisher --config configs/tiny.json --set " + set + " --out " + (out / "bad").string());
    CHECK(bad.code == 2);
    CHECK_THAT(bad.err, Catch::Contains(key));
    CHECK(lines(bad.err) == 1);
  }
  CHECK_FALSE(fs::exists(out / "bad"));
}

namespace {
// A tiny training run for the evaluation and export tests: 4 steps, one test scene and the ColorChecker.
std::string eval_test_sets(const fs::path& base) { return test::tiny_run_sets(base / "data", 4); }
}  // namespace

TEST_CASE("hsd_train, hsd_eval and hsd_export with the Wiener pre-inversion: the exported model scores the checkpoint's metrics", "[app][eval][preinverse]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_eval_wiener";
  fs::remove_all(base);
  const std::string sets = eval_test_sets(base) + " --set model.preinverse=wiener --set model.preinverse_reg=0.02";
  const Run t = run("hsd_train --config configs/tiny.json" + sets + " --out " + (base / "run").string());
  INFO(t.err);
  REQUIRE(t.code == 0);
  const std::string ck = " --checkpoint " + (base / "run/checkpoints/last.pt").string();
  const Run r = run("hsd_eval --config configs/tiny.json" + sets + ck + " --out " + (base / "eval").string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  const Run ex = run("hsd_export --config configs/tiny.json" + sets + ck + " --out " + (base / "export").string());
  INFO(ex.err);
  REQUIRE(ex.code == 0);
  const std::string model = (base / "export/reconstructor.pt").string();
  const Run em = run("hsd_eval --config configs/tiny.json" + sets + " --model " + model + " --out " + (base / "eval_model").string());
  INFO(em.err);
  REQUIRE(em.code == 0);
  const auto j = nlohmann::json::parse(std::ifstream(base / "eval" / "metrics.json"));
  const auto jm = nlohmann::json::parse(std::ifstream(base / "eval_model" / "metrics.json"));
  for (const char* k : {"hs_psnr_db", "hs_ssim", "depth_rmse_m", "baseline_upsampling_hs_psnr_db"})
    CHECK(jm[k].get<double>() == Approx(j[k].get<double>()).epsilon(1e-4));
  // Python's torch.jit.load runs it (the FFTs included).
  const std::string py = "/usr/bin/python3 -c \"import torch; m = torch.jit.load('" + model +
                         "'); hs, z = m(torch.rand(1, 3, 20, 18)); assert tuple(z.shape) == (1, 1, 20, 18); "
                         "assert tuple(m.preinverse_psf.shape[1:3]) == (3, 15), m.preinverse_psf.shape; print('ok')\" 2>&1";
  CHECK(capture(py).first.find("ok") != std::string::npos);
}

TEST_CASE("hsd_eval and hsd_export on a trained checkpoint: metrics, report, pictures, TorchScript", "[app][eval]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_eval";
  fs::remove_all(base);
  const std::string sets = eval_test_sets(base);
  REQUIRE(run("hsd_train --config configs/tiny.json" + sets + " --out " + (base / "run").string()).code == 0);
  const Run r = run("hsd_eval --config configs/tiny.json" + sets + " --checkpoint " + (base / "run/checkpoints/last.pt").string() +
                    " --out " + (base / "eval").string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(std::ifstream(base / "eval" / "metrics.json"));
  for (const char* k : {"hs_psnr_db", "hs_ssim", "lum_psnr_db", "lum_ssim", "depth_rmse_m", "depth_mae_m",
                        "colorchecker_reflectance_rmse", "baseline_constant_depth_rmse_m", "baseline_constant_depth_mae_m",
                        "baseline_upsampling_hs_psnr_db", "baseline_upsampling_hs_ssim"})
    CHECK(j.contains(k));
  CHECK(j["scenes"].size() == 2);  // the test scene and the ColorChecker
  CHECK(j["hs_ssim"].get<double>() <= 1.0);
  for (const char* f : {"report.md", "psf_atlas.png", "colorchecker_spectra.png", "scene_test_000_compare.png",
                        "scene_test_000_spectra.png"})
    CHECK(fs::exists(base / "eval" / f));
  // Export the same checkpoint: TorchScript with the contract's signature and attributes.
  const Run ex = run("hsd_export --config configs/tiny.json" + sets + " --checkpoint " +
                     (base / "run/checkpoints/last.pt").string() + " --out " + (base / "export").string());
  INFO(ex.err);
  REQUIRE(ex.code == 0);
  for (const char* f : {"reconstructor.pt", "doe_height.pt", "psf_atlas.png", "config.json"}) CHECK(fs::exists(base / "export" / f));
  const std::string py = "/usr/bin/python3 -c \"import torch; m = torch.jit.load('" + (base / "export/reconstructor.pt").string() +
                         "'); hs, z = m(torch.rand(1, 3, 20, 18)); assert tuple(hs.shape) == (1, 3, 20, 18), hs.shape; "
                         "assert tuple(z.shape) == (1, 1, 20, 18); assert m.wavelengths_m.dtype == torch.float64; "
                         "assert m.depth_range_m.numel() == 2; print('ok', m.camera)\" 2>&1";
  CHECK(capture(py).first.find("ok canon") != std::string::npos);
  // hsd_eval with the exported model (and the DOE beside it) gives the checkpoint's metrics.
  const Run em = run("hsd_eval --config configs/tiny.json" + sets + " --model " + (base / "export/reconstructor.pt").string() +
                     " --out " + (base / "eval_model").string());
  INFO(em.err);
  REQUIRE(em.code == 0);
  const auto jm = nlohmann::json::parse(std::ifstream(base / "eval_model" / "metrics.json"));
  for (const char* k : {"hs_psnr_db", "hs_ssim", "depth_rmse_m", "colorchecker_reflectance_rmse",
                        "baseline_constant_depth_rmse_m", "baseline_upsampling_hs_psnr_db"})
    CHECK(jm[k].get<double>() == Approx(j[k].get<double>()).epsilon(1e-4));
  CHECK(run("hsd_eval --config configs/tiny.json" + sets + " --out " + (base / "bad").string()).code == 2);  // neither
  // Reconstruct an sRGB PNG and a linear EXR with the exported model, in tiles.
  {
    const torch::Tensor rgb = torch::rand({3, 70, 66});
    data::write_srgb_png((base / "frame.png").string(), rgb);
    data::write_channels_exr((base / "frame.exr").string(), rgb, {"R", "G", "B"});
    for (const char* in : {"frame.png", "frame.exr"}) {
      const fs::path out = base / (std::string("rec_") + in);
      const Run rr = run("hsd_reconstruct --model " + (base / "export/reconstructor.pt").string() + " --input " +
                         (base / in).string() + " --tile 32 --overlap 0 --out " + out.string());
      INFO(rr.err);
      REQUIRE(rr.code == 0);
      const torch::Tensor z = data::read_channels_exr((out / "depth.exr").string(), {"Z"});
      CHECK(z.sizes() == torch::IntArrayRef({1, 70, 66}));
      CHECK(z.min().item<double>() > 0.0);
      CHECK(fs::exists(out / "hs.exr"));
      CHECK(fs::exists(out / "hs_srgb.png"));
      CHECK(fs::exists(out / "depth.png"));
    }
    // hs.exr carries S0.<nm> channels for the model's bands.
    const torch::Tensor hsx = data::read_channels_exr((base / "rec_frame.png" / "hs.exr").string(),
                                                      {"S0.450nm", "S0.550nm", "S0.650nm"});
    CHECK(hsx.sizes() == torch::IntArrayRef({3, 70, 66}));
    // bfloat16 inference: the same files, close to float32.
    const Run r16 = run("hsd_reconstruct --model " + (base / "export/reconstructor.pt").string() + " --input " +
                        (base / "frame.png").string() + " --tile 32 --overlap 0 --precision bfloat16 --out " +
                        (base / "rec16").string());
    INFO(r16.err);
    REQUIRE(r16.code == 0);
    const torch::Tensor z32 = data::read_channels_exr((base / "rec_frame.png" / "depth.exr").string(), {"Z"});
    const torch::Tensor z16 = data::read_channels_exr((base / "rec16" / "depth.exr").string(), {"Z"});
    CHECK((z16 - z32).abs().max().item<double>() < 0.05 * z32.abs().max().item<double>());
    CHECK(run("hsd_reconstruct --model " + (base / "export/reconstructor.pt").string() + " --input " +
              (base / "frame.png").string() + " --precision half --out " + (base / "rb").string()).code == 2);
    // Bad inputs: a file that is not a model, a missing model, a missing image.
    Run b = run("hsd_reconstruct --model " + (base / "export/doe_height.pt").string() + " --input " + (base / "frame.png").string() +
                " --out " + (base / "rb").string());
    CHECK(b.code == 2);
    CHECK_THAT(b.err, Catch::Contains("doe_height.pt"));
    b = run("hsd_reconstruct --model " + (base / "none.pt").string() + " --input " + (base / "frame.png").string() + " --out " +
            (base / "rb").string());
    CHECK(b.code == 2);
    b = run("hsd_reconstruct --model " + (base / "export/reconstructor.pt").string() + " --input " + (base / "nope.png").string() +
            " --out " + (base / "rb").string());
    CHECK(b.code == 2);
    CHECK_THAT(b.err, Catch::Contains("nope.png"));
  }
  Run bad = run("hsd_eval --config configs/tiny.json" + sets + " --checkpoint " + (base / "none.pt").string() + " --out " +
                (base / "bad").string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("none.pt"));
  bad = run("hsd_eval --config configs/tiny.json" + sets + " --checkpoint " + (base / "run/checkpoints/last.pt").string() +
            " --split training --out " + (base / "bad").string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("--split"));
}

TEST_CASE("hsd_ablate runs the four DOE arms and the control, without a shell, and writes the table and the plot", "[app][eval]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_ablate";
  fs::remove_all(base);
  const std::string sets =
      test::tiny_run_sets(base / "data", 3) + " --set fisher.design_samples=32 --set fisher.window_px=9 --set fisher.steps=3"
      " --set fisher.zernike_modes=6";
  // A --set value with a quote and a command substitution reaches the sub-runs
  // as text: no shell sees it (it used to break the runs or run the command).
  const fs::path marker = base / "injected";
  const std::string note = " --set \"_note=Baek's DOE \\$(touch " + marker.string() + ")\"";
  const Run r = run("hsd_ablate --config configs/tiny.json" + sets + note + " --seeds 0,1 --out " + (base / "out").string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  CHECK_FALSE(fs::exists(marker));
  for (const char* f : {"ablation.md", "ablation.csv", "error_vs_time.png", "fisher/crlb.json",
                        "fresnel_fixed_seed0/eval/metrics.json", "fisher_learned_seed1/run/metrics.csv",
                        "all_in_focus_seed1/eval/metrics.json"})
    CHECK(fs::exists(base / "out" / f));
  std::ifstream md_file(base / "out" / "ablation.md");
  const std::string md((std::istreambuf_iterator<char>(md_file)), std::istreambuf_iterator<char>());
  CHECK_THAT(md, Catch::Contains("all-in-focus control") && Catch::Contains("2 standard errors") &&
                     Catch::Contains("RMSE / constant"));
  std::ifstream csv(base / "out" / "ablation.csv");
  std::string line;
  int rows = 0;
  std::getline(csv, line);
  CHECK_THAT(line, Catch::Contains("hs_psnr_db_mean") && Catch::Contains("depth_rmse_m_std"));
  while (std::getline(csv, line)) {
    ++rows;
    CHECK_THAT(line, Catch::Contains(",2,"));  // two seeds per arm
  }
  CHECK(rows == 5);
  const Run bad = run("hsd_ablate --config configs/tiny.json --seeds 0,x --out " + (base / "bad").string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("--seeds"));
}

TEST_CASE("hsd_scenes --real builds the held-out real-derived set and hsd_eval --data evaluates it", "[app][data][eval]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_real";
  fs::remove_all(base);
  const Run r = run("hsd_scenes --config configs/tiny.json --set data.generator.width_px=48 --set data.generator.height_px=40 --real --out " +
                    (base / "real").string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto m = nlohmann::json::parse(std::ifstream(base / "real" / "manifest.json"));
  REQUIRE(m["scenes"].size() == 8);  // 7 CAVE placements and the Aloe
  for (const auto& s : m["scenes"]) {
    CHECK(s["split"] == "test");
    const data::SpectralScene sc = data::read_scene_exr((base / "real" / s["file"].get<std::string>()).string());
    CHECK(sc.spectral.min().item<float>() >= 0.0f);
    CHECK(sc.spectral.max().item<float>() <= 1.0f);
    CHECK((sc.mask > 0.5).any().item<bool>());
  }
  // The fronto-parallel CAVE scenes: one depth each, real spectra (the cube's, band-integrated).
  const data::SpectralScene front = data::read_scene_exr((base / "real" / "cave_front_mid.exr").string());
  CHECK((front.depth_m.max() - front.depth_m.min()).item<float>() < 1e-3f);
  CHECK(fs::exists(base / "real" / "realism.json"));
  // A tiny trained system, evaluated on the real-derived set with --data.
  const std::string sets = test::tiny_run_sets(base / "synthetic");
  REQUIRE(run("hsd_train --config configs/tiny.json" + sets + " --out " + (base / "run").string()).code == 0);
  const Run e = run("hsd_eval --config configs/tiny.json" + sets + " --checkpoint " + (base / "run/checkpoints/last.pt").string() +
                    " --data " + (base / "real").string() + " --out " + (base / "eval").string());
  INFO(e.err);
  REQUIRE(e.code == 0);
  const auto j = nlohmann::json::parse(std::ifstream(base / "eval" / "metrics.json"));
  CHECK(j["scenes"].size() == 8);
  CHECK(std::isfinite(j["depth_rmse_m"].get<double>()));
  // --data without a manifest: exit 2 naming the flag.
  const Run bad = run("hsd_eval --config configs/tiny.json --checkpoint " + (base / "run/checkpoints/last.pt").string() +
                      " --data " + (base / "nothing").string() + " --out " + (base / "eval2").string());
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("--data"));
}
