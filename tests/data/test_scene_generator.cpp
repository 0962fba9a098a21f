// The procedural scene generator (data/scene_generator.h): deterministic,
// varied, in range; the ColorChecker scene and its layout.
#include <catch2/catch.hpp>
#include <filesystem>

#include "common/error.h"
#include "data/reflectance_library.h"
#include "data/scene_generator.h"
#include "helpers.h"
#include "scene_helpers.h"

using namespace hsd;
using test::nm;
using test::small_generator;

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
