// Band resampling by integration of the piecewise-linear spectrum (data/band_resample.h).
#include <catch2/catch.hpp>
#include <filesystem>

#include "common/error.h"
#include "common/log.h"
#include "data/band_resample.h"
#include "data/dataset.h"
#include "helpers.h"
#include "scene_helpers.h"

using namespace hsd;
using test::nm;
using test::flat_scene;

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
