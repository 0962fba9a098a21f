// Sensor noise and read-out: σ statistics, shot-noise variance ∝ signal,
// clipping, quantization levels with a straight-through gradient, seeding.
#include <catch2/catch.hpp>
#include <cmath>

#include "optics/sensor_noise.h"

using namespace hsd::optics;

TEST_CASE("noise: read noise has the configured sigma and is reproducible for a seed", "[sensor][noise]") {
  const torch::Tensor J = torch::full({2, 3, 128, 128}, 0.5, torch::kFloat64);
  NoiseModel m;
  m.std_max = 0.02;
  CHECK(m.std_min < 0.0);  // the default: a fixed σ = std_max, as sensor.noise_std_min
  m.saturation = 0.0;
  auto g1 = at::detail::createCPUGenerator(7), g2 = at::detail::createCPUGenerator(7);
  const torch::Tensor a = apply_sensor_noise(J, m, g1), b = apply_sensor_noise(J, m, g2);
  CHECK(torch::equal(a, b));
  CHECK((a - J).std().item<double>() == Approx(0.02).epsilon(0.02));
  CHECK(std::fabs((a - J).mean().item<double>()) < 1e-3);
  // a σ range: each image's σ lies in it
  m.std_min = 0.01;
  m.std_max = 0.05;
  const torch::Tensor c = apply_sensor_noise(J, m, at::detail::createCPUGenerator(3)) - J;
  for (int64_t i = 0; i < 2; ++i) {
    const double s = c[i].std().item<double>();
    CHECK(s > 0.0095);
    CHECK(s < 0.0525);
  }
}

TEST_CASE("noise: shot noise variance grows with the signal as J / photons", "[sensor][noise]") {
  NoiseModel m;
  m.photons_at_saturation = 1000.0;
  m.saturation = 0.0;
  for (double level : {0.1, 0.8}) {
    const torch::Tensor J = torch::full({1, 1, 256, 256}, level, torch::kFloat64);
    const double var = (apply_sensor_noise(J, m, at::detail::createCPUGenerator(1)) - J).var().item<double>();
    CHECK(var == Approx(level / 1000.0).epsilon(0.03));
  }
  // finite gradient at zero signal
  torch::Tensor z = torch::zeros({1, 1, 4, 4}, torch::kFloat64).set_requires_grad(true);
  apply_sensor_noise(z, m, at::detail::createCPUGenerator(2)).sum().backward();
  CHECK(torch::isfinite(z.grad()).all().item<bool>());
}

TEST_CASE("noise: clipping at saturation and quantization with a straight-through gradient", "[sensor][noise]") {
  NoiseModel m;
  m.saturation = 1.0;
  m.bit_depth = 3;  // 7 levels of 1/7
  torch::Tensor J = torch::linspace(-0.5, 1.5, 101, torch::kFloat64).view({1, 1, 1, 101}).set_requires_grad(true);
  const torch::Tensor y = apply_sensor_noise(J, m);
  CHECK(y.min().item<double>() >= 0.0);
  CHECK(y.max().item<double>() <= 1.0);
  const torch::Tensor levels = y.detach() * 7.0;
  CHECK((levels - levels.round()).abs().max().item<double>() < 1e-12);
  CHECK(std::get<0>(torch::_unique(levels.round())).numel() == 8);
  y.sum().backward();
  // gradient 1 inside [0, 1] (straight-through), 0 where clipped
  const torch::Tensor g = J.grad().view(-1);
  CHECK(g[50].item<double>() == 1.0);
  CHECK(g[0].item<double>() == 0.0);
  CHECK(g[100].item<double>() == 0.0);
}
