// DOE families, the height-map file and the fabrication constraints.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "common/config.h"
#include "common/error.h"
#include "helpers.h"
#include "optics/doe.h"

using namespace hsd;

TEST_CASE("Fresnel DOE: one period of height and the phase of a lens mod 2pi at the design wavelength", "[doe]") {
  const int64_t N = 128;
  const double lambda0 = 550e-9, n0 = 1.46, z0 = 0.8, s = 0.05, delta = 5e-6;
  const torch::Tensor h = optics::fresnel_height(N, delta, lambda0, n0, z0, s);
  const double period = lambda0 / (n0 - 1.0);
  CHECK(h.min().item<double>() >= 0.0);
  CHECK(h.max().item<double>() < period);
  const torch::Tensor x = (torch::arange(N, torch::kFloat64) - 0.5 * (N - 1)) * delta;
  const torch::Tensor r2 = x.view({1, -1}).pow(2) + x.view({-1, 1}).pow(2);
  const double k0 = 2 * M_PI / lambda0;
  const torch::Tensor lens_phase = -0.5 * k0 * r2 * (1.0 / z0 + 1.0 / s);
  const torch::Tensor diff = torch::remainder(h * k0 * (n0 - 1.0) - lens_phase + M_PI, 2 * M_PI) - M_PI;
  CHECK(diff.abs().max().item<double>() < 1e-9);
}

TEST_CASE("spiral DOE: heights in range and unlike a plain Fresnel lens", "[doe]") {
  const auto mat = optics::Material::load("fused_silica_malitson1965");
  const int64_t N = 128;
  const torch::Tensor h = optics::spiral_height(N, 5e-6, 420e-9, 660e-9, 3, mat, 0.8, 0.05);
  CHECK(h.min().item<double>() >= 0.0);
  CHECK(h.max().item<double>() < 660e-9 / (mat.index(660e-9) - 1.0));
  // 3-fold rotational symmetry: rotating by 120° maps the map onto itself (approximately, on a grid)
  const torch::Tensor flat = optics::fresnel_height(N, 5e-6, 540e-9, mat.index(540e-9), 0.8, 0.05);
  CHECK((h - flat).abs().mean().item<double>() > 1e-8);  // not simply a Fresnel lens
}

TEST_CASE("height-map files round-trip and mismatches are refused", "[doe][io]") {
  const auto dir = std::filesystem::temp_directory_path() / "hsd_test_doe";
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "h.pt").string();
  const torch::Tensor h = optics::random_height(16, 1e-6, 3);
  optics::save_height_file(path, h, 4e-6);
  const torch::Tensor back = optics::load_height_file(path, 16, 4e-6);
  CHECK((back - h).abs().max().item<double>() < 1e-12 + 1e-6 * 1e-6);
  CHECK_THROWS_WITH(optics::load_height_file(path, 32, 4e-6), Catch::Contains("h.pt") && Catch::Contains("doe_samples"));
  CHECK_THROWS_WITH(optics::load_height_file(path, 16, 5e-6), Catch::Contains("doe_pitch_m"));
  CHECK_THROWS_WITH(optics::load_height_file((dir / "none.pt").string(), 16, 4e-6), Catch::Contains("no such file"));
  const std::string junk = (dir / "junk.pt").string();
  { std::ofstream(junk) << "not a pickle"; }
  CHECK_THROWS_AS(optics::load_height_file(junk, 16, 4e-6), InputError);
}

TEST_CASE("DOE init families from the config", "[doe]") {
  const std::string paper = test::source_path("configs/tiny.json");
  const auto mat = optics::Material::load("fused_silica_malitson1965");
  for (const char* init : {"flat", "fresnel", "spiral", "random"}) {
    const Config c = load_config(paper, {std::string("optics.doe.init=") + init});
    const torch::Tensor h = optics::initial_height(c.optics, mat, 1);
    CHECK(h.sizes() == torch::IntArrayRef({c.optics.doe_samples, c.optics.doe_samples}));
    CHECK(torch::isfinite(h).all().item<bool>());
  }
  const Config r = load_config(paper, {"optics.doe.init=random"});
  CHECK(torch::equal(optics::initial_height(r.optics, mat, 5), optics::initial_height(r.optics, mat, 5)));
  CHECK_FALSE(torch::equal(optics::initial_height(r.optics, mat, 5), optics::initial_height(r.optics, mat, 6)));
  const Config f = load_config(paper, {"optics.doe.init=fisher", "optics.doe.fisher_path=/nonexistent/fisher_height.pt"});
  CHECK_THROWS_WITH(optics::initial_height(f.optics, mat, 0), Catch::Contains("hsd_fisher") && Catch::Contains("optics.doe.init"));
  const Config file = load_config(paper, {"optics.doe.init=file:/nonexistent.pt"});
  CHECK_THROWS_WITH(optics::initial_height(file.optics, mat, 0), Catch::Contains("/nonexistent.pt"));
}

TEST_CASE("DOE constraints: heights wrap into 0..max with gradient 1", "[doe]") {
  const torch::Tensor h0 = torch::tensor({-0.25e-6, 0.5e-6, 1.75e-6}, torch::kFloat64).view({1, 3});
  optics::Doe doe(h0, 1e-6, 0, 1e-6);
  const torch::Tensor h = doe.height();
  CHECK(h[0][0].item<double>() == Approx(0.75e-6));
  CHECK(h[0][1].item<double>() == Approx(0.5e-6));
  CHECK(h[0][2].item<double>() == Approx(0.75e-6));
  h.sum().backward();
  CHECK(torch::allclose(doe.parameter().grad(), torch::ones_like(h0)));
}
