// Lifting sRGB to spectra (data/rgbd_import.h): the colour is reproduced and
// the spectra stay in range.
#include <catch2/catch.hpp>
#include <filesystem>

#include "common/error.h"
#include "data/preview.h"
#include "data/rgbd_import.h"
#include "helpers.h"
#include "optics/spectrum.h"
#include "scene_helpers.h"

using namespace hsd;
using test::nm;

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
