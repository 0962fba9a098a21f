// The patch sampler (data/patch_sampler.h): never an invalid pixel,
// deterministic, depth coverage, flips and rotations.
#include <catch2/catch.hpp>
#include <filesystem>
#include <random>

#include "common/error.h"
#include "data/illuminant_augment.h"
#include "data/patch_sampler.h"
#include "helpers.h"
#include "scene_helpers.h"

using namespace hsd;
using test::nm;
using test::flat_scene;

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

TEST_CASE("data: with an overhang, windows reach past the scene's border by it, the scene continued by its replicated edge, and their centres cover the whole scene",
          "[data]") {
  const auto w = nm({450, 550, 650});
  const int64_t H = 30, W = 40, S = 20, o = 6;  // windows of 20 px whose centre 8 px is the patch
  std::vector<data::LoadedScene> scenes(1);
  data::SpectralScene s = flat_scene(w, H, W, 0.5, 1.0);
  // value = 1000 row + column: every pixel tells where it came from.
  s.spectral = (torch::arange(W, torch::kFloat32).view({1, 1, W}) + 1000 * torch::arange(H, torch::kFloat32).view({1, H, 1}))
                   .expand({3, H, W})
                   .clone();
  scenes[0].scene = s;
  const data::PatchSampler inside(scenes, S, 1, 1), over(scenes, S, 1, 1, o);
  CHECK(inside.candidates() == (H - S + 1) * (W - S + 1));
  CHECK(over.candidates() == (H - S + 1 + 2 * o) * (W - S + 1 + 2 * o));
  const data::IlluminantBank bank({"D65"}, w, 10e-9);
  int64_t y_min = H, y_max = -H, x_min = W, x_max = -W;
  for (data::PatchSpec p : over.draw(2000, 7, bank.size(), 1.0, 1.0)) {
    REQUIRE(p.y >= -o);
    REQUIRE(p.y + S <= H + o);
    y_min = std::min(y_min, p.y), y_max = std::max(y_max, p.y), x_min = std::min(x_min, p.x), x_max = std::max(x_max, p.x);
    p.flip = false, p.rot90 = 0, p.lighting = {0, 1.0};
    const torch::Tensor got = over.extract(p, &bank).spectral[0] / bank.spectrum(0)[0];
    // By hand: each window pixel is the scene's nearest pixel (clamped coordinates).
    const torch::Tensor rows = (torch::arange(S) + p.y).clamp(0, H - 1), cols = (torch::arange(S) + p.x).clamp(0, W - 1);
    const torch::Tensor expect = (cols.view({1, S}) + 1000 * rows.view({S, 1})).to(torch::kFloat32);
    REQUIRE(torch::allclose(got, expect, 1e-5, 1e-3));
  }
  // Windows at every overhanging extreme were drawn: the patch (the window's
  // centre, o px in) then touches each border of the scene.
  CHECK(y_min == -o);
  CHECK(y_max == H - S + o);
  CHECK(x_min == -o);
  CHECK(x_max == W - S + o);
  CHECK_THROWS_AS(data::PatchSampler(scenes, S, 1, 1, -1), InputError);
}
