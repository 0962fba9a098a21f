// Config parsing: extends, --set, typed values, and one clear error naming the
// key path for unknown keys, wrong types and out-of-range values.
#include <catch2/catch.hpp>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "common/config.h"
#include "common/error.h"
#include "common/log.h"
#include "common/sample_stats.h"
#include "helpers.h"

using namespace hsd;

namespace {
std::string error_of(const std::vector<std::string>& overrides, const std::string& file = "configs/paper.json") {
  try {
    load_config(test::source_path(file), overrides);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}
std::string tmp_file(const std::string& name, const std::string& text) {
  const auto dir = std::filesystem::temp_directory_path() / "hsd_test_config";
  std::filesystem::create_directories(dir);
  const auto p = dir / name;
  std::ofstream(p) << text;
  return p.string();
}
}  // namespace

TEST_CASE("paper config resolves with the paper's values", "[config]") {
  const Config c = load_config(test::source_path("configs/paper.json"), {});
  REQUIRE(c.optics.wavelengths_nm.size() == 25);
  CHECK(c.optics.wavelengths_nm.front() == 420.0);
  CHECK(c.optics.wavelengths_nm.back() == 660.0);
  REQUIRE(c.optics.depths_m.size() == 7);
  CHECK(c.optics.depths_m.front() == Approx(0.4));
  CHECK(c.optics.depths_m.back() == Approx(2.0));
  // linear in inverse depth
  for (size_t i = 1; i + 1 < 7; ++i)
    CHECK(1.0 / c.optics.depths_m[i] == Approx(0.5 * (1.0 / c.optics.depths_m[i - 1] + 1.0 / c.optics.depths_m[i + 1])).epsilon(1e-5));
  CHECK(c.optics.sensor_distance_m == 0.05);
  CHECK(c.optics.pixel_pitch_m == 6.22e-6);
  CHECK(c.optics.band_width_m() == Approx(10e-9));
  CHECK(c.optics.psf_size % 2 == 1);
  CHECK(c.resolved.contains("optics"));
  CHECK_FALSE(c.resolved.contains("extends"));
}

TEST_CASE("set overrides parse JSON values and bare words as strings", "[config]") {
  const Config c = load_config(test::source_path("configs/paper.json"),
                               {"optics.psf_size=31", "optics.doe.init=spiral", "optics.wavelengths_nm=[500,600]"});
  CHECK(c.optics.psf_size == 31);
  CHECK(c.optics.doe.init == DoeFamily::spiral);
  CHECK(c.optics.wavelengths_nm == std::vector<double>{500, 600});
  CHECK(c.resolved["optics"]["psf_size"] == 31);
}

TEST_CASE("typed choices: a file choice keeps its path, lists keep their order, words round-trip", "[config]") {
  const Config c = load_config(test::source_path("configs/paper.json"),
                               {"optics.doe.init=\"file:/tmp/h.pt\"", "optics.psf_source=all_in_focus", "fisher.nuisance=[\"N\",\"x\"]",
                                "data.generator.layouts={\"tabletop\":2,\"classic_tabletop\":1}", "device=cpu"});
  CHECK((c.optics.doe.init == DoeFamily::file));
  CHECK(c.optics.doe.init_path == "/tmp/h.pt");
  CHECK(choice_word(c.optics.doe.init, c.optics.doe.init_path) == "file:/tmp/h.pt");
  CHECK((c.optics.psf_source == PsfSource::all_in_focus));
  CHECK(c.optics.psf_path.empty());
  CHECK((c.fisher.nuisance == std::vector<NuisanceParam>{NuisanceParam::N, NuisanceParam::x}));
  // JSON objects list their keys sorted, so the layouts come in name order whatever the file's order.
  REQUIRE(c.data.generator.layouts.size() == 2);
  CHECK((c.data.generator.layouts[0] == std::make_pair(SceneLayout::classic_tabletop, 1.0)));
  CHECK((c.data.generator.layouts[1] == std::make_pair(SceneLayout::tabletop, 2.0)));
  CHECK((c.device == ComputeDevice::cpu));
  for (const auto& [v, name] : choice_names(DoeFamily{})) {
    DoeFamily back;
    CHECK((v == DoeFamily::file || (choice_of(name, &back) && back == v)));
  }
}

TEST_CASE("the inert key data.patches of saved configs is accepted with a warning", "[config]") {
  const int before = log::warning_count();
  const Config c = load_config(test::source_path("configs/paper.json"), {"data.patches=20000"});
  CHECK(log::warning_count() == before + 1);
  CHECK(c.data.patch_size_px > 0);
  CHECK(error_of({"data.patches=\"many\""}).find("data.patches") != std::string::npos);  // still type-checked
}

TEST_CASE("bad configs name the key path", "[config]") {
  CHECK_THAT(error_of({"optics.psf_sizee=3"}), Catch::Contains("optics.psf_sizee") && Catch::Contains("unknown"));
  CHECK_THAT(error_of({"optics.psf_size=64"}), Catch::Contains("optics.psf_size") && Catch::Contains("odd"));
  CHECK_THAT(error_of({"optics.psf_size=\"big\""}), Catch::Contains("optics.psf_size") && Catch::Contains("integer"));
  CHECK_THAT(error_of({"optics.sensor_distance_m=-1"}), Catch::Contains("optics.sensor_distance_m"));
  CHECK_THAT(error_of({"optics.depths_m=[1, 0]"}), Catch::Contains("optics.depths_m"));
  CHECK_THAT(error_of({"optics.wavelengths_nm=[600, 500]"}), Catch::Contains("increasing"));
  CHECK_THAT(error_of({"optics.aperture_diameter_m=0.01"}), Catch::Contains("optics.aperture_diameter_m") && Catch::Contains("grid"));
  CHECK_THAT(error_of({"optics.doe.init=cubic"}), Catch::Contains("optics.doe.init"));
  CHECK_THAT(error_of({"optics.doe.init=\"file:\""}), Catch::Contains("optics.doe.init") && Catch::Contains("path"));
  CHECK_THAT(error_of({"optics.psf_source=\"files:x\""}), Catch::Contains("optics.psf_source") && Catch::Contains("file:PATH"));
  CHECK_THAT(error_of({"fisher.nuisance=[\"x\",\"q\"]"}), Catch::Contains("fisher.nuisance") && Catch::Contains("q"));
  CHECK_THAT(error_of({"data.generator.layouts={\"forest\":1}"}), Catch::Contains("data.generator.layouts.forest"));
  CHECK_THAT(error_of({"device=tpu"}), Catch::Contains("device"));
  CHECK_THAT(error_of({"sensor.noise_std=-0.1"}), Catch::Contains("sensor.noise_std"));
  CHECK_THAT(error_of({"train.batch_size=0"}), Catch::Contains("train.batch_size"));
  CHECK_THAT(error_of({"train.doe_every=0"}), Catch::Contains("train.doe_every"));
  CHECK_THAT(error_of({"train.doe_adam_beta1=1"}), Catch::Contains("train.doe_adam_beta1"));
  CHECK_THAT(error_of({"train.base_doe_gradient_scale=-1"}), Catch::Contains("train.base_doe_gradient_scale"));
  CHECK_THAT(error_of({"model.residual=\"image\"", "model.read_illuminant=false", "model.fuse_defocus_reader=false",
                       "train.base_doe_gradient_scale=2"}),
             Catch::Contains("train.base_doe_gradient_scale") && Catch::Contains("spectral_wiener"));
  CHECK_THAT(error_of({"nosuch"}), Catch::Contains("dotted.key=VALUE"));
  CHECK_THAT(error_of({}, "configs/missing.json"), Catch::Contains("missing.json") && Catch::Contains("not found"));
}

TEST_CASE("extends chains merge objects and detect cycles", "[config]") {
  const std::string base = tmp_file("b.json", R"({"optics": {"psf_size": 9, "doe": {"init": "flat"}}})");
  const std::string a = tmp_file("a.json", R"({"extends": "b.json", "optics": {"doe": {"spiral_wings": 5}},
    "_note": "free text"})");
  Json j = load_json_with_extends(a);
  CHECK(j["optics"]["psf_size"] == 9);
  CHECK(j["optics"]["doe"]["init"] == "flat");
  CHECK(j["optics"]["doe"]["spiral_wings"] == 5);
  tmp_file("c1.json", R"({"extends": "c2.json"})");
  const std::string c2 = tmp_file("c2.json", R"({"extends": "c1.json"})");
  CHECK_THROWS_WITH(load_json_with_extends(c2), Catch::Contains("cycle"));
  const std::string broken = tmp_file("broken.json", R"({"optics": )");
  CHECK_THROWS_WITH(load_json_with_extends(broken), Catch::Contains("broken.json") && Catch::Contains("invalid JSON"));
}

TEST_CASE("sample_stats gives the mean and the n-1 standard deviation", "[common]") {
  const SampleStats s = sample_stats({1.0, 2.0, 4.0});
  CHECK(s.n == 3);
  CHECK(s.mean == Approx(7.0 / 3.0));
  CHECK(s.sd == Approx(std::sqrt(((1 - 7.0 / 3) * (1 - 7.0 / 3) + (2 - 7.0 / 3) * (2 - 7.0 / 3) + (4 - 7.0 / 3) * (4 - 7.0 / 3)) / 2.0)));
  CHECK(sample_stats({5.0}).sd == 0.0);
  CHECK(sample_stats({}).n == 0);
  CHECK(sample_stats({}).mean == 0.0);
}

TEST_CASE("configs/base.json states the structs' defaults (one source of them)", "[config]") {
  // Every scalar key of base.json read with the struct's default as fallback
  // must hold that default: a default changed in one place and not the other fails here.
  const Json base = load_json_with_extends(test::source_path("configs/base.json"));
  std::vector<std::string> unlike;
  parse_config(base, &unlike);
  std::string list;
  for (const auto& k : unlike) list += k + " ";
  INFO("keys of base.json unlike the struct defaults: " << list);
  CHECK(unlike.empty());
  // The check can fail: one changed key is named.
  Json changed = base;
  changed["optics"]["mft_rank_tol"] = 1e-3;
  changed["optics"]["doe"]["quantization_levels"] = 8;
  unlike.clear();
  parse_config(changed, &unlike);
  CHECK(std::find(unlike.begin(), unlike.end(), "optics.mft_rank_tol") != unlike.end());
  CHECK(std::find(unlike.begin(), unlike.end(), "optics.doe.quantization_levels") != unlike.end());
}
