// Integration of intensity over a sensor pixel's area by Gauss–Legendre
// quadrature (a tensor-product rule, n nodes per axis).
//
// Why it can be exact: the intensity behind an aperture of diameter D is band
// limited — its spectrum is the pupil autocorrelation, zero beyond D/(λs) cycles
// per metre on the sensor. Over one pixel of pitch p a component of frequency f
// turns by at most a = π f p radians either side of the pixel centre, and an
// n-node Gauss rule integrates cos(a u) on [−1, 1] with an error that falls like
// a^(2n)/(2n)!. So a few nodes integrate a pixel to 1e-3 or better, and long
// wavelengths (smaller D p/(λs)) need fewer nodes than short ones. Point-sampling
// pixel centres (n = 1) is the usual shortcut and costs percent-level error.
#pragma once
#include <vector>

namespace hsd::optics {

struct Quadrature1D {
  std::vector<double> nodes;    // offsets in pixel units, in (−1/2, 1/2), ascending
  std::vector<double> weights;  // sum to 1
};

// n-node Gauss–Legendre rule mapped to [−1/2, 1/2] with weights summing to 1.
Quadrature1D gauss_legendre(int n);

// Worst error, over frequencies 0..f_max, of the n-node rule integrating a unit
// cosine across one pixel: max_f |Σ w cos(2π f p u) − sinc(f p)|, with
// cycles_per_pixel = f_max·p. Relative to the pixel's DC value, this bounds the
// error of every Fourier component of a band-limited intensity.
double pixel_quadrature_error(int n, double cycles_per_pixel);

// Smallest n (≤ 16) with pixel_quadrature_error(n, cycles_per_pixel) ≤ tol.
int choose_pixel_nodes(double cycles_per_pixel, double tol);

// Highest spatial frequency of the intensity, in cycles per pixel: D·p/(λ·s).
double intensity_cycles_per_pixel(double aperture_diameter_m, double pixel_pitch_m, double wavelength_m,
                                  double sensor_distance_m);

}  // namespace hsd::optics
