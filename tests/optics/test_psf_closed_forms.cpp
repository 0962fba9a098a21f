// The PSF simulator against closed forms: the Airy pattern of an in-focus
// Fresnel DOE, the diffractive focal shift f(λ) = f0 λ0/λ, the deflection of a
// prism (linear height ramp) with the contract's +x/+y orientation, and
// Parseval (energy through the aperture = energy on a window holding all of it).
#include <catch2/catch.hpp>
#include <cmath>

#include "helpers.h"
#include "optics/aperture.h"
#include "optics/doe.h"
#include "optics/pixel_quadrature.h"

using namespace hsd;

namespace {

// Fraction of the light through a circular aperture D that falls on the pixel
// centred at (x, y), ideal Airy pattern, integrated with an 8×8 Gauss rule.
double airy_pixel_fraction(double x, double y, double p, double lambda, double s, double D) {
  const auto q = optics::gauss_legendre(8);
  double sum = 0.0;
  for (size_t a = 0; a < q.nodes.size(); ++a)
    for (size_t b = 0; b < q.nodes.size(); ++b) {
      const double r = std::hypot(x + q.nodes[a] * p, y + q.nodes[b] * p);
      const double v = M_PI * D * r / (lambda * s);
      const double amp = v < 1e-9 ? 1.0 : 2.0 * std::cyl_bessel_j(1.0, v) / v;
      sum += q.weights[a] * q.weights[b] * amp * amp;
    }
  return sum * p * p * M_PI * D * D / (4.0 * lambda * lambda * s * s);
}

}  // namespace

TEST_CASE("circular aperture: edge cells get their covered fraction, exactly as the full 8x8 sub-sample grid gives",
          "[psf][closed-form]") {
  // The reference: every sub-sample of every cell (what the function did
  // before it sub-sampled only the edge cells).
  auto full_grid = [](int64_t n, double pitch, double diameter) {
    const int64_t ss = 8;
    const torch::Tensor x = ((torch::arange(n * ss, torch::kFloat64) + 0.5) / double(ss) - 0.5 * double(n)) * pitch;
    const double r = 0.5 * diameter;
    const torch::Tensor r2 = x.view({-1, 1}).pow(2) + x.view({1, -1}).pow(2);
    return torch::avg_pool2d((r2 <= r * r).to(torch::kFloat64).view({1, 1, n * ss, n * ss}), {ss, ss}).view({n, n});
  };
  const double pitch = 8e-6;
  // even and odd grids; apertures filling, overfilling, inside one cell, tangent to cell edges
  for (const auto& [n, d] : std::vector<std::pair<int64_t, double>>{
           {64, 64 * pitch}, {63, 40.3 * pitch}, {32, 50 * pitch}, {16, 0.7 * pitch}, {17, 0.3 * pitch}, {40, 20 * pitch}}) {
    const torch::Tensor a = optics::aperture_transmission(n, pitch, d, ApertureShape::circle);
    INFO("N = " << n << ", D = " << d / pitch << " pitches");
    CHECK(torch::equal(a, full_grid(n, pitch, d)));
  }
  // The area is the disc's to the sub-sampling's accuracy.
  const torch::Tensor a = optics::aperture_transmission(256, pitch, 200 * pitch, ApertureShape::circle);
  CHECK(a.sum().item<double>() == Approx(M_PI * 100.0 * 100.0).epsilon(1e-3));
  CHECK(a.min().item<double>() == 0.0);
  CHECK(a.max().item<double>() == 1.0);
}

TEST_CASE("in-focus Fresnel DOE gives the Airy pattern", "[psf][closed-form]") {
  const double lambda = 550e-9, s = 0.05, z0 = 1.0, D = 2.0e-3, p = 1e-6, delta = 8e-6;
  const int64_t N = 256, P = 61;
  auto spec = test::make_spec({lambda}, {z0}, N, delta, D, P, p, s, 4);
  // Cell-centre sampling is exact for an ideal, continuous lens (its total phase
  // is constant); the pixelated element (sinc cells) is checked below.
  spec.pupil_cell_integration = CellIntegration::midpoint;
  const optics::PsfSimulator sim(spec);
  const torch::Tensor h = optics::fresnel_height(N, delta, lambda, 1.5, z0, s);
  const auto out = sim.compute(h);
  const torch::Tensor frac = out.psf[0][0] * out.energy_in_window[0][0];  // fraction of aperture energy per pixel

  torch::Tensor ideal = torch::zeros({P, P}, torch::kFloat64);
  auto ia = ideal.accessor<double, 2>();
  for (int64_t i = 0; i < P; ++i)
    for (int64_t j = 0; j < P; ++j) ia[i][j] = airy_pixel_fraction((j - P / 2) * p, (i - P / 2) * p, p, lambda, s, D);

  const double rel_l1 = ((frac - ideal).abs().sum() / ideal.sum()).item<double>();
  INFO("relative L1 to the ideal Airy pattern: " << rel_l1);
  CHECK(rel_l1 < 0.01);

  const double strehl = frac[P / 2][P / 2].item<double>() / ia[P / 2][P / 2];
  INFO("Strehl ratio: " << strehl);
  CHECK(strehl >= 0.9);
  CHECK(strehl <= 1.01);

  // The same lens as cells of constant height (8 µm): inside each cell the
  // source and propagation phases keep their local ramp of slope k(1/z + 1/s)ξ,
  // which the cell cannot follow, so each cell's amplitude falls to
  // sinc(k(1/z + 1/s)ξδ/2)·sinc(k(1/z + 1/s)ηδ/2) and the peak to
  // Airy · [Σ A sinc sinc / Σ A]² (the staircase lens's efficiency).
  {
    auto cells = spec;
    cells.pupil_cell_integration = CellIntegration::sinc;
    const auto o = optics::PsfSimulator(cells).compute(h);
    const double peak = (o.psf[0][0] * o.energy_in_window[0][0])[P / 2][P / 2].item<double>();
    const torch::Tensor x = optics::centred_coordinates(N, delta);
    const double slope = 2 * M_PI / lambda * (1.0 / z0 + 1.0 / s);
    const torch::Tensor u = x * slope * delta / 2;
    const torch::Tensor sx = torch::sin(u) / u;
    const torch::Tensor A = optics::aperture_transmission(N, delta, D, ApertureShape::circle);
    const double eff = ((A * torch::outer(sx, sx)).sum() / A.sum()).item<double>();
    const double predicted = ia[P / 2][P / 2] * eff * eff;
    INFO("pixelated lens: peak " << peak << ", predicted " << predicted << " (cell efficiency " << eff << ")");
    CHECK(eff < 0.97);  // a visible effect at this pitch
    CHECK(peak == Approx(predicted).epsilon(0.01));
    cells.pupil_cell_integration = CellIntegration::sinc_cross;  // the cross term vanishes on the axis
    const auto oc = optics::PsfSimulator(cells).compute(h);
    CHECK((oc.psf[0][0] * oc.energy_in_window[0][0])[P / 2][P / 2].item<double>() == Approx(predicted).epsilon(0.01));
  }

  // First dark ring at 1.22 λ s / D along the central row (and column).
  const double r1_px = 1.22 * lambda * s / D / p;  // 16.8 pixels
  const torch::Tensor row = out.psf[0][0][P / 2].narrow(0, P / 2, P / 2 + 1);  // centre -> right edge
  const int64_t lo = int64_t(r1_px * 0.6), hi = std::min<int64_t>(P / 2, int64_t(r1_px * 1.4));
  const int64_t ring = lo + row.narrow(0, lo, hi - lo).argmin().item<int64_t>();
  INFO("dark ring at pixel " << ring << ", predicted " << r1_px);
  CHECK(std::fabs(double(ring) - r1_px) <= 1.0);
  CHECK(row[ring].item<double>() < 0.02 * row[0].item<double>());
  const torch::Tensor col = out.psf[0][0].select(1, P / 2).narrow(0, P / 2, P / 2 + 1);
  CHECK(lo + col.narrow(0, lo, hi - lo).argmin().item<int64_t>() == ring);
}

TEST_CASE("Fresnel DOE focus moves with wavelength as f = f0 lambda0 / lambda", "[psf][closed-form]") {
  const double lambda0 = 550e-9, s = 0.05, z0 = 1.0, D = 2.0e-3, delta = 8e-6, p = 2e-6;
  const int64_t N = 256, P = 15;
  const torch::Tensor h = optics::fresnel_height(N, delta, lambda0, 1.5, z0, s);
  for (double lambda : {540e-9, 560e-9, 580e-9}) {
    // Predicted: 1/z + 1/s = 1/f(λ) = (λ/λ0)(1/z0 + 1/s).
    const double u_pred = (lambda / lambda0) * (1.0 / z0 + 1.0 / s) - 1.0 / s;
    std::vector<double> depths;
    const int K = 31;
    const double span = 0.6;
    for (int k = 0; k < K; ++k) depths.push_back(1.0 / (u_pred - span + 2.0 * span * k / (K - 1)));
    auto spec = test::make_spec({lambda}, depths, N, delta, D, P, p, s, 3);
    const auto out = optics::PsfSimulator(spec).compute(h);
    // Peak irradiance: centre pixel's share of the light through the aperture.
    const torch::Tensor peak = out.psf[0].select(1, P / 2).select(1, P / 2) * out.energy_in_window[0];
    const int64_t k = peak.argmax().item<int64_t>();
    REQUIRE(k > 0);
    REQUIRE(k < K - 1);
    const double a = peak[k - 1].item<double>(), b = peak[k].item<double>(), c = peak[k + 1].item<double>();
    const double offset = 0.5 * (a - c) / (a - 2.0 * b + c);  // parabola vertex, in steps
    const double step = 2.0 * span / (K - 1);
    const double u_found = u_pred - span + (double(k) + offset) * step;
    INFO("lambda " << lambda * 1e9 << " nm: best focus 1/z = " << u_found << " /m, predicted " << u_pred);
    CHECK(std::fabs(u_found - u_pred) < 0.03);
  }
}

TEST_CASE("a height ramp deflects the PSF by (n-1) slope s toward the thicker side along +x columns and +y rows",
          "[psf][closed-form]") {
  const double lambda = 550e-9, s = 0.05, z0 = 1.0, D = 2.0e-3, delta = 8e-6, p = 2e-6, n = 1.5;
  const int64_t N = 256, P = 41;
  const torch::Tensor x = (torch::arange(N, torch::kFloat64) - 0.5 * (N - 1)) * delta;
  const torch::Tensor X = x.view({1, -1}).expand({N, N}), Y = x.view({-1, 1}).expand({N, N});
  // Continuous (unwrapped) lens focusing z0 on the sensor, achromatic for constant n.
  const torch::Tensor lens = -(X * X + Y * Y) * (0.5 * (1.0 / z0 + 1.0 / s) / (n - 1.0));
  // 6 and 4.5 pixel shifts (whole and half pixels: the sub-pixel peak fit is exact by symmetry there)
  for (double slope : {4.8e-4, 3.6e-4})
  for (double lambda_k : {450e-9, lambda, 650e-9}) {
    const double shift_px = (n - 1.0) * slope * s / p;
    auto spec = test::make_spec({lambda_k}, {z0}, N, delta, D, P, p, s, 4, torch::kFloat64, n);
    const optics::PsfSimulator sim(spec);
    const auto px = sim.compute(lens + slope * X).psf[0][0];
    const auto py = sim.compute(lens + slope * Y).psf[0][0];
    auto peak_xy = [&](const torch::Tensor& img) {
      const int64_t idx = img.argmax().item<int64_t>();
      const int64_t r = idx / P, c = idx % P;
      auto sub = [&](double a, double b, double cc) { return 0.5 * (a - cc) / (a - 2.0 * b + cc); };
      const double dx = sub(img[r][c - 1].item<double>(), img[r][c].item<double>(), img[r][c + 1].item<double>());
      const double dy = sub(img[r - 1][c].item<double>(), img[r][c].item<double>(), img[r + 1][c].item<double>());
      return std::make_pair(double(c - P / 2) + dx, double(r - P / 2) + dy);
    };
    const auto [xx, xy] = peak_xy(px);
    const auto [yx, yy] = peak_xy(py);
    INFO("lambda " << lambda_k * 1e9 << " nm: x-ramp peak (" << xx << ", " << xy << "), y-ramp peak (" << yx << ", "
                   << yy << "), predicted shift " << shift_px << " px");
    CHECK(std::fabs(xx - shift_px) < 0.05);
    CHECK(std::fabs(xy) < 0.05);
    CHECK(std::fabs(yy - shift_px) < 0.05);
    CHECK(std::fabs(yx) < 0.05);
  }
}

TEST_CASE("Parseval: a window holding a whole period gets all the light", "[psf][closed-form]") {
  // The sampled pupil's transform repeats every λs/δ on the sensor; a window of
  // exactly one period holds all the light that went through the aperture.
  const double lambda = 500e-9, s = 0.05, delta = 10e-6;
  const int64_t N = 32, P = 33;
  const double p = lambda * s / delta / double(P);
  const torch::Tensor h = optics::random_height(N, 2e-6, 7);
  for (const ApertureShape shape : {ApertureShape::circle, ApertureShape::square}) {
    auto spec = test::make_spec({lambda}, {0.3, 1.0, 1e6}, N, delta, 0.3e-3, P, p, s, 8);
    spec.aperture_shape = shape;
    spec.pupil_cell_integration = CellIntegration::midpoint;  // Parseval of the discrete transform
    const auto e = optics::PsfSimulator(spec).compute(h).energy_in_window;
    INFO(choice_name(shape) << ": energy in window " << e);
    CHECK(((e - 1.0).abs().max()).item<double>() < 1e-9);
    auto spec32 = spec;
    spec32.real_dtype = torch::kFloat32;
    const auto e32 = optics::PsfSimulator(spec32).compute(h).energy_in_window;
    CHECK(((e32 - 1.0).abs().max()).item<double>() < 1e-4);
  }
}
