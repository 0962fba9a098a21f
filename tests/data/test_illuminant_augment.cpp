// Illuminant augmentation (data/illuminant_augment.h): D65 × a perfect white
// is D65, and the 29 illuminants load.
#include <catch2/catch.hpp>
#include <filesystem>

#include "common/error.h"
#include "data/illuminant_augment.h"
#include "helpers.h"
#include "optics/spectrum.h"
#include "scene_helpers.h"

using namespace hsd;
using test::nm;

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
