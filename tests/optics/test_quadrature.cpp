// Gauss–Legendre pixel quadrature: exactness on polynomials, its error model,
// and the automatic per-wavelength choice of nodes.
#include <catch2/catch.hpp>
#include <cmath>

#include "optics/pixel_quadrature.h"

using namespace hsd::optics;

TEST_CASE("Gauss-Legendre rules integrate polynomials of degree 2n-1 exactly", "[quadrature]") {
  for (int n = 1; n <= 10; ++n) {
    const auto q = gauss_legendre(n);
    double wsum = 0.0;
    for (double w : q.weights) wsum += w;
    CHECK(wsum == Approx(1.0).margin(1e-14));
    for (int d = 0; d <= 2 * n - 1; ++d) {
      double s = 0.0;
      for (size_t i = 0; i < q.nodes.size(); ++i) s += q.weights[i] * std::pow(q.nodes[i], d);
      // mean of u^d over [-1/2, 1/2]
      const double exact = (d % 2) ? 0.0 : std::pow(0.5, d) / (d + 1);
      CHECK(s == Approx(exact).margin(1e-14));
    }
    // and not degree 2n (for even 2n the rule must differ)
    double s = 0.0;
    for (size_t i = 0; i < q.nodes.size(); ++i) s += q.weights[i] * std::pow(q.nodes[i], 2 * n);
    CHECK(std::fabs(s - std::pow(0.5, 2 * n) / (2 * n + 1)) > 1e-16);
  }
}

TEST_CASE("pixel quadrature error falls with nodes and the automatic choice meets its tolerance", "[quadrature]") {
  for (double cpp : {0.2, 0.5, 0.8, 1.5}) {
    double prev = 1e9;
    for (int n = 1; n <= 6; ++n) {
      const double e = pixel_quadrature_error(n, cpp);
      CHECK(e <= prev + 1e-15);
      prev = e;
    }
    const int n = choose_pixel_nodes(cpp, 1e-3);
    CHECK(pixel_quadrature_error(n, cpp) <= 1e-3);
    if (n > 1) CHECK(pixel_quadrature_error(n - 1, cpp) > 1e-3);
  }
  // point sampling is badly wrong at the paper's 420 nm band (0.59 cycles/pixel)
  CHECK(pixel_quadrature_error(1, 0.59) > 0.3);
  // longer wavelengths (fewer cycles per pixel) never need more nodes
  CHECK(choose_pixel_nodes(intensity_cycles_per_pixel(2e-3, 6.22e-6, 660e-9, 0.05), 1e-3) <=
        choose_pixel_nodes(intensity_cycles_per_pixel(2e-3, 6.22e-6, 420e-9, 0.05), 1e-3));
}
