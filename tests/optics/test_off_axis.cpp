// Off-axis PSFs (optics/off_axis_psf.h) against the on-axis simulator and the
// closed form of a paraxial lens: an off-axis point imaged at u0 = −s tan θ
// with the same Airy pattern, to the extent the paraxial approximation holds.
#include <catch2/catch.hpp>
#include <cmath>

#include <torch/torch.h>

#include "helpers.h"
#include "optics/doe.h"
#include "optics/off_axis_psf.h"
#include "optics/pixel_quadrature.h"
#include "optics/psf.h"

using namespace hsd;

namespace {

double rel_l1(const torch::Tensor& a, const torch::Tensor& b) { return ((a - b).abs().sum() / b.abs().sum()).item<double>(); }

// The pixel-integrated Airy pattern of aperture D at distance s, normalised to sum 1 in the window.
torch::Tensor airy_window(int64_t P, double p, double lambda, double s, double D) {
  const auto q = optics::gauss_legendre(8);
  torch::Tensor a = torch::zeros({P, P}, torch::kFloat64);
  auto acc = a.accessor<double, 2>();
  for (int64_t i = 0; i < P; ++i)
    for (int64_t j = 0; j < P; ++j) {
      double sum = 0;
      for (size_t u = 0; u < q.nodes.size(); ++u)
        for (size_t v = 0; v < q.nodes.size(); ++v) {
          const double r = std::hypot((j - P / 2 + q.nodes[u]) * p, (i - P / 2 + q.nodes[v]) * p);
          const double x = M_PI * D * r / (lambda * s);
          const double amp = x < 1e-9 ? 1.0 : 2.0 * std::cyl_bessel_j(1.0, x) / x;
          sum += q.weights[u] * q.weights[v] * amp * amp;
        }
      acc[i][j] = sum;
    }
  return a / a.sum();
}

}  // namespace

TEST_CASE("off-axis PSF at 0 degrees is the on-axis simulator's", "[off_axis][psf]") {
  auto spec = test::make_spec({500e-9, 600e-9}, {0.5, 2.0}, 128, 8e-6, 0.9e-3, 21, 4e-6, 0.05, 3);
  spec.pupil_cell_integration = CellIntegration::midpoint;
  spec.mft_rank_tol = 0.0;
  auto gen = at::detail::createCPUGenerator(2);
  const torch::Tensor h = 1e-6 * at::rand({128, 128}, gen, torch::TensorOptions().dtype(torch::kFloat64));
  const torch::Tensor on = optics::PsfSimulator(spec).compute(h).psf;
  const torch::Tensor off = optics::off_axis_psf(spec, h, 0.0);
  for (int64_t l = 0; l < 2; ++l)
    for (int64_t z = 0; z < 2; ++z) {
      INFO("band " << l << " depth " << z);
      CHECK(rel_l1(off[l][z], on[l][z]) < 1e-4);  // the exact spherical wave's 4th-order terms: ~1e-5 rad
    }
}

TEST_CASE("a paraxial lens images an off-axis point at -s tan(theta) with the Airy pattern, and astigmatism grows as theta^2",
          "[off_axis][psf][closed-form]") {
  const double lambda = 550e-9, s = 0.05, z0 = 1.0, D = 2.0e-3, p = 2e-6, delta = 8e-6;
  const int64_t N = 256, P = 41;
  auto spec = test::make_spec({lambda}, {z0}, N, delta, D, P, p, s, 4);
  spec.pupil_cell_integration = CellIntegration::midpoint;
  spec.mft_rank_tol = 0.0;
  const torch::Tensor h = optics::fresnel_height(N, delta, lambda, 1.5, z0, s);
  const torch::Tensor airy = airy_window(P, p, lambda, s, D);
  const torch::Tensor on = optics::off_axis_psf(spec, h, 0.0)[0][0];
  CHECK(rel_l1(on, airy) < 0.01);
  double previous = 0.0;
  for (double deg : {1.0, 3.0, 8.0}) {
    const double th = deg * M_PI / 180.0;
    const torch::Tensor off = optics::off_axis_psf(spec, h, th)[0][0];
    const auto c = test::centroid(off);  // pixels from the window centre, which sits at u0 = -s tan(theta)
    const double d = rel_l1(off, airy);
    INFO(deg << " deg: relative L1 to the Airy pattern " << d << ", centroid (" << c.first << ", " << c.second
             << ") px, neglected third-order phase " << optics::off_axis_neglected_phase_rad(spec, th) << " rad");
    CHECK(std::abs(c.first) < 0.05);
    CHECK(std::abs(c.second) < 0.05);
    if (deg == 1.0) CHECK(d < 0.02);  // oblique astigmatism k a² (1/z0 + 1/s)(1 − cos³θ)/2 = 0.05 rad
    CHECK(d > previous);              // and it grows with the angle
    previous = d;
  }
}
