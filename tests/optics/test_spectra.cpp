// Spectral tables, band integration and dispersion formulas: against the
// tabulated values that came with them (a self-consistency check: the table
// was computed from the same formulas), and fused silica against the indices
// Malitson measured (an independent check).
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <utility>
#include <vector>
#include <nlohmann/json.hpp>

#include "common/error.h"
#include "optics/material.h"
#include "optics/spectrum.h"

using namespace hsd;
using namespace hsd::optics;

TEST_CASE("dispersion formulas reproduce the tabulated indices", "[material]") {
  std::ifstream f(spectra_path("refractive_index_materials.json"));
  const auto j = nlohmann::json::parse(f);
  const SpectralTable table = SpectralTable::load_csv(spectra_path("refractive_index_visible.csv"));
  int compared = 0;
  for (auto it = j["materials"].begin(); it != j["materials"].end(); ++it) {
    const Material m = Material::load(it.key());
    CHECK(m.index(587.56e-9) == Approx(it.value()["n_at_587.56nm"].get<double>()).margin(2e-6));
    for (double nm = 380; nm <= 780; nm += 5) {
      const double t = table.value(it.key(), nm);
      if (t == 0.0) continue;  // empty cell: outside the formula's range
      INFO(it.key() << " at " << nm << " nm");
      CHECK(m.index(nm * 1e-9) == Approx(t).margin(1.5e-6));
      CHECK(m.in_valid_range(nm * 1e-9));
      ++compared;
    }
  }
  CHECK(compared > 300);
  CHECK_THROWS_WITH(Material::load("unobtainium"), Catch::Contains("optics.material"));
}

TEST_CASE("fused silica's formula meets Malitson's measured indices at the visible lines", "[material]") {
  // Malitson, "Interspecimen comparison of the refractive index of fused
  // silica", JOSA 55, 1205 (1965), Table I: the mean index measured on the
  // Corning, Dynasil and General Electric specimens (20 °C, wavelengths in
  // air, µm), here the lines from 400 to 710 nm (the paper's Sellmeier
  // formula, which optics/material.cpp evaluates, fits them to within
  // 8e-6 there). The measured values are data, not the formula's output.
  const std::vector<std::pair<double, double>> measured{
      {0.404656, 1.469620}, {0.435835, 1.466690}, {0.467816, 1.464300}, {0.486133, 1.463130}, {0.508582, 1.461870},
      {0.546074, 1.460080}, {0.576959, 1.458850}, {0.579065, 1.458770}, {0.587561, 1.458470}, {0.589262, 1.458400},
      {0.643847, 1.456710}, {0.656272, 1.456370}, {0.667815, 1.456070}, {0.706519, 1.455150}};
  const Material silica = Material::load("fused_silica_malitson1965");
  double worst = 0;
  for (const auto& [um, n] : measured) {
    INFO(um << " um");
    CHECK(silica.index(um * 1e-6) == Approx(n).margin(1.2e-5));
    worst = std::max(worst, std::abs(silica.index(um * 1e-6) - n));
  }
  CHECK(worst > 0.0);  // measurements, not the formula's own values
  // The dispersion across the visible, which sets the DOE's chromatic behaviour: n(F) − n(C) measured 0.006760.
  CHECK(silica.index(0.486133e-6) - silica.index(0.656272e-6) == Approx(1.463130 - 1.456370).margin(2e-5));
}

TEST_CASE("band means integrate the piecewise-linear table exactly", "[spectrum]") {
  const SpectralTable cam = SpectralTable::load_csv(spectra_path("camera_sensitivity_canon_5d_mark_iii.csv"));
  // Within one 5 nm table interval the curve is linear: the band mean is the centre value.
  CHECK(cam.band_mean("g", 551.0, 554.0) == Approx(cam.value("g", 552.5)).epsilon(1e-12));
  // Over two intervals: exact trapezoids.
  const double expected = 0.5 * (0.5 * (cam.value("g", 545) + cam.value("g", 550)) + 0.5 * (cam.value("g", 550) + cam.value("g", 555)));
  CHECK(cam.band_mean("g", 545.0, 555.0) == Approx(expected).epsilon(1e-12));
  // Outside the table the curve is zero.
  CHECK(cam.band_mean("g", 370.0, 380.0) == 0.0);
}

TEST_CASE("camera response is 3 x L and non-negative with the expected dominant channels", "[spectrum]") {
  std::vector<double> w;
  for (int i = 0; i < 25; ++i) w.push_back((420 + 10 * i) * 1e-9);
  const torch::Tensor omega = camera_response("canon_5d_mark_iii", w, 10e-9);
  REQUIRE(omega.sizes() == torch::IntArrayRef({3, 25}));
  CHECK(omega.min().item<double>() >= 0.0);
  CHECK(omega[1][13].item<double>() > omega[0][13].item<double>());  // 550 nm: G > R
  CHECK(omega[1][13].item<double>() > omega[2][13].item<double>());  // 550 nm: G > B
  CHECK(omega[2][3].item<double>() > omega[0][3].item<double>());    // 450 nm: B > R
  CHECK(omega[0][22].item<double>() > omega[2][22].item<double>());  // 640 nm: R > B
  CHECK(omega.sum(1).max().item<double>() == Approx(1.0).epsilon(1e-6));  // largest row sums to 1
  CHECK_THROWS_AS(camera_response("box_camera", w, 10e-9), InputError);
}

TEST_CASE("illuminants are band means scaled to a maximum of 1", "[spectrum]") {
  const std::vector<double> w{450e-9, 550e-9, 650e-9};
  const torch::Tensor e = illuminant_bands("E", w, 10e-9);  // equal energy
  CHECK((e - 1.0).abs().max().item<double>() < 1e-6);
  const torch::Tensor a = illuminant_bands("A", w, 10e-9);  // incandescent: rises toward red
  CHECK(a[2].item<double>() == Approx(1.0));
  CHECK(a[0].item<double>() < a[1].item<double>());
  CHECK_THROWS_WITH(illuminant_bands("D99", w, 10e-9), Catch::Contains("sensor.illuminant"));
}

TEST_CASE("display colours follow the spectrum", "[spectrum]") {
  const auto blue = wavelength_display_rgb(450e-9), green = wavelength_display_rgb(530e-9), red = wavelength_display_rgb(640e-9);
  CHECK(blue[2] == 1.0);
  CHECK(green[1] == 1.0);
  CHECK(red[0] == 1.0);
}
