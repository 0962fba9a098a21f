// Spectral-EXR scenes (Fichet et al. 2021 layout): channel names, round trips
// in float and half, and one clear error per malformed scene.
#include <catch2/catch.hpp>
#include <limits>
#include <filesystem>
#include <fstream>

#include "common/error.h"
#include "data/scene_exr.h"

using namespace hsd;
using namespace hsd::data;
namespace fs = std::filesystem;

namespace {
std::string tmp(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / "hsd_test_exr";
  fs::create_directories(d);
  return (d / name).string();
}
SpectralScene small_scene(int64_t H = 8, int64_t W = 10) {
  SpectralScene s;
  s.wavelengths_m = {450e-9, 552.5e-9, 650e-9};
  s.spectral = torch::rand({3, H, W});
  s.depth_m = 0.5 + torch::rand({1, H, W});
  s.mask = torch::ones({1, H, W});
  return s;
}
}  // namespace

TEST_CASE("spectral channel names follow the Fichet layout with comma or point decimals", "[exr]") {
  CHECK(parse_spectral_channel("T.550nm")->wavelength_m == Approx(550e-9));
  CHECK(parse_spectral_channel("T.550,000000nm")->wavelength_m == Approx(550e-9));
  CHECK(parse_spectral_channel("S0.552.5nm")->prefix == "S0");
  CHECK(parse_spectral_channel("S0.552.5nm")->wavelength_m == Approx(552.5e-9));
  CHECK(parse_spectral_channel("T.0,55um")->wavelength_m == Approx(550e-9));
  CHECK_FALSE(parse_spectral_channel("T.abcnm"));
  CHECK_FALSE(parse_spectral_channel("R"));
  CHECK_FALSE(parse_spectral_channel("T.550"));
  CHECK(spectral_channel_name("T", 552.5e-9) == "T.552,5nm");
  CHECK(spectral_channel_name("S0", 550e-9) == "S0.550nm");
}

TEST_CASE("scenes round-trip through EXR in float and half", "[exr]") {
  const SpectralScene s = small_scene();
  for (bool half : {false, true}) {
    const std::string p = tmp(half ? "half.exr" : "float.exr");
    write_scene_exr(p, s, half);
    const SpectralScene r = read_scene_exr(p);
    REQUIRE(r.wavelengths_m.size() == 3);
    CHECK(r.wavelengths_m[1] == Approx(552.5e-9));
    CHECK(r.kind == SpectralKind::Reflectance);
    const double tol = half ? 2e-3 : 0.0;
    CHECK((r.spectral - s.spectral).abs().max().item<double>() <= tol);
    CHECK((r.depth_m - s.depth_m).abs().max().item<double>() <= tol * 2);
    CHECK(torch::equal(r.mask, s.mask));
  }
}

TEST_CASE("malformed scenes are refused naming the file and the problem", "[exr]") {
  const SpectralScene s = small_scene();
  // NaN depth in a valid pixel: refused; in a masked-out pixel: fine.
  SpectralScene bad = s;
  bad.depth_m = s.depth_m.clone();
  bad.depth_m[0][2][3] = std::nan("");
  write_scene_exr(tmp("nan_depth.exr"), bad);
  CHECK_THROWS_WITH(read_scene_exr(tmp("nan_depth.exr")), Catch::Contains("nan_depth.exr") && Catch::Contains("Z") &&
                                                               Catch::Contains("x=3, y=2"));
  bad.mask = s.mask.clone();
  bad.mask[0][2][3] = 0.0;
  write_scene_exr(tmp("nan_masked.exr"), bad);
  CHECK_NOTHROW(read_scene_exr(tmp("nan_masked.exr")));
  bad.depth_m[0][2][3] = -1.0;
  bad.mask = s.mask;
  write_scene_exr(tmp("neg_depth.exr"), bad);
  CHECK_THROWS_WITH(read_scene_exr(tmp("neg_depth.exr")), Catch::Contains("negative"));
  // Missing Z, no spectral channels, mixed kinds.
  write_channels_exr(tmp("no_z.exr"), s.spectral, {"T.450nm", "T.550nm", "T.650nm"});
  CHECK_THROWS_WITH(read_scene_exr(tmp("no_z.exr")), Catch::Contains("missing depth channel Z"));
  write_channels_exr(tmp("rgb.exr"), torch::cat({s.spectral, s.depth_m}), {"R", "G", "B", "Z"});
  CHECK_THROWS_WITH(read_scene_exr(tmp("rgb.exr")), Catch::Contains("no spectral channels"));
  write_channels_exr(tmp("mixed.exr"), torch::cat({s.spectral, s.depth_m}), {"T.450nm", "S0.550nm", "T.650nm", "Z"});
  CHECK_THROWS_WITH(read_scene_exr(tmp("mixed.exr")), Catch::Contains("mixes"));
  write_channels_exr(tmp("badname.exr"), torch::cat({s.spectral, s.depth_m}), {"T.450nm", "T.5x0nm", "T.650nm", "Z"});
  CHECK_THROWS_WITH(read_scene_exr(tmp("badname.exr")), Catch::Contains("badname.exr") && Catch::Contains("T.5x0nm"));
  // Inf in a valid pixel's spectrum.
  bad = s;
  bad.spectral = s.spectral.clone();
  bad.spectral[1][1][1] = std::numeric_limits<float>::infinity();
  write_scene_exr(tmp("inf_spec.exr"), bad);
  CHECK_THROWS_WITH(read_scene_exr(tmp("inf_spec.exr")), Catch::Contains("inf_spec.exr") && Catch::Contains("NaN or Inf"));
  // Truncated and missing files.
  write_scene_exr(tmp("whole.exr"), s);
  const auto size = fs::file_size(tmp("whole.exr"));
  fs::copy_file(tmp("whole.exr"), tmp("truncated.exr"), fs::copy_options::overwrite_existing);
  fs::resize_file(tmp("truncated.exr"), size / 2);
  CHECK_THROWS_WITH(read_scene_exr(tmp("truncated.exr")), Catch::Contains("truncated.exr"));
  CHECK_THROWS_AS(read_scene_exr(tmp("nonexistent.exr")), InputError);
  { std::ofstream(tmp("text.exr")) << "not an exr"; }
  CHECK_THROWS_WITH(read_scene_exr(tmp("text.exr")), Catch::Contains("unreadable"));
}
