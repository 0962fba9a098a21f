#include "optics/pixel_quadrature.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace hsd::optics {

Quadrature1D gauss_legendre(int n) {
  if (n < 1 || n > 64) throw std::invalid_argument("gauss_legendre: n must be in [1, 64]");
  Quadrature1D q;
  q.nodes.resize(size_t(n));
  q.weights.resize(size_t(n));
  // Newton iteration on P_n from Chebyshev-like starting points (Numerical Recipes' gauleg idea).
  for (int i = 0; i < (n + 1) / 2; ++i) {
    double x = std::cos(M_PI * (i + 0.75) / (n + 0.5));
    double dp = 1.0;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1.0, p1 = 0.0;
      for (int j = 1; j <= n; ++j) {
        const double p2 = p1;
        p1 = p0;
        p0 = ((2.0 * j - 1.0) * x * p1 - (j - 1.0) * p2) / j;
      }
      dp = n * (x * p0 - p1) / (x * x - 1.0);
      const double dx = p0 / dp;
      x -= dx;
      if (std::fabs(dx) < 1e-16) break;
    }
    const double w = 2.0 / ((1.0 - x * x) * dp * dp);
    // nodes on [−1, 1] -> [−1/2, 1/2]; weights (sum 2) -> sum 1
    q.nodes[size_t(i)] = -0.5 * x;
    q.nodes[size_t(n - 1 - i)] = 0.5 * x;
    q.weights[size_t(i)] = q.weights[size_t(n - 1 - i)] = 0.5 * w;
  }
  if (n % 2 == 1) q.nodes[size_t(n / 2)] = 0.0;
  return q;
}

double pixel_quadrature_error(int n, double cycles_per_pixel) {
  const Quadrature1D q = gauss_legendre(n);
  double worst = 0.0;
  const int steps = 256;
  for (int s = 1; s <= steps; ++s) {
    const double fp = cycles_per_pixel * s / steps;
    const double a = 2.0 * M_PI * fp;
    double sum = 0.0;
    for (size_t i = 0; i < q.nodes.size(); ++i) sum += q.weights[i] * std::cos(a * q.nodes[i]);
    const double exact = std::sin(M_PI * fp) / (M_PI * fp);
    worst = std::max(worst, std::fabs(sum - exact));
  }
  return worst;
}

int choose_pixel_nodes(double cycles_per_pixel, double tol) {
  for (int n = 1; n < 16; ++n)
    if (pixel_quadrature_error(n, cycles_per_pixel) <= tol) return n;
  return 16;
}

double intensity_cycles_per_pixel(double aperture_diameter_m, double pixel_pitch_m, double wavelength_m,
                                  double sensor_distance_m) {
  return aperture_diameter_m * pixel_pitch_m / (wavelength_m * sensor_distance_m);
}

}  // namespace hsd::optics
