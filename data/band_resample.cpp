#include "data/band_resample.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <torch/torch.h>

#include "common/error.h"
#include "common/log.h"

namespace hsd::data {

namespace {
// Value at x of the k-th basis function of the interpolant (hat functions,
// flat beyond the ends).
double basis(const std::vector<double>& xs, size_t k, double x) {
  const size_t n = xs.size();
  if (n == 1) return 1.0;
  if (x <= xs.front()) return k == 0 ? 1.0 : 0.0;
  if (x >= xs.back()) return k == n - 1 ? 1.0 : 0.0;
  if (k > 0 && x >= xs[k - 1] && x <= xs[k]) return (x - xs[k - 1]) / (xs[k] - xs[k - 1]);
  if (k + 1 < n && x >= xs[k] && x <= xs[k + 1]) return (xs[k + 1] - x) / (xs[k + 1] - xs[k]);
  return 0.0;
}
std::string nm_list(const std::vector<double>& w) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%zu bands %.1f-%.1f nm", w.size(), w.front() * 1e9, w.back() * 1e9);
  return buf;
}
}  // namespace

torch::Tensor band_resampling_matrix(const std::vector<double>& in_m, const std::vector<double>& centres_m,
                                     double band_width_m, const std::string& what) {
  if (in_m.empty() || centres_m.empty()) input_error(what, "no bands to resample");
  if (!(band_width_m > 0.0)) input_error(what, "band width must be > 0");
  const size_t n = in_m.size();
  for (size_t k = 1; k < n; ++k)
    if (!(in_m[k] > in_m[k - 1])) input_error(what, "channel wavelengths must be distinct and ascending");
  const double spacing = n > 1 ? (in_m.back() - in_m.front()) / double(n - 1) : band_width_m;
  const double lo_ok = in_m.front() - 0.5 * spacing - 1e-12, hi_ok = in_m.back() + 0.5 * spacing + 1e-12;
  torch::Tensor R = torch::zeros({int64_t(centres_m.size()), int64_t(n)}, torch::kFloat64);
  auto acc = R.accessor<double, 2>();
  for (size_t b = 0; b < centres_m.size(); ++b) {
    const double a = centres_m[b] - 0.5 * band_width_m, e = centres_m[b] + 0.5 * band_width_m;
    if (a < lo_ok || e > hi_ok) {
      char buf[260];
      std::snprintf(buf, sizeof buf, "optics.wavelengths_nm band %.1f nm (%.1f-%.1f nm) lies outside the channels (%s, usable %.1f-%.1f nm)",
                    centres_m[b] * 1e9, a * 1e9, e * 1e9, nm_list(in_m).c_str(), lo_ok * 1e9, hi_ok * 1e9);
      input_error(what, buf);
    }
    // Breakpoints: the band's ends and the channel wavelengths inside it; the
    // interpolant is linear between them, so the trapezoid rule is exact.
    std::vector<double> xs{a, e};
    for (double x : in_m)
      if (x > a && x < e) xs.push_back(x);
    std::sort(xs.begin(), xs.end());
    for (size_t i = 0; i + 1 < xs.size(); ++i) {
      const double w = 0.5 * (xs[i + 1] - xs[i]) / band_width_m;
      for (size_t k = 0; k < n; ++k) acc[int64_t(b)][int64_t(k)] += w * (basis(in_m, k, xs[i]) + basis(in_m, k, xs[i + 1]));
    }
  }
  return R;
}

bool same_bands(const std::vector<double>& a_m, const std::vector<double>& b_m) {
  if (a_m.size() != b_m.size()) return false;
  for (size_t i = 0; i < a_m.size(); ++i)
    if (std::fabs(a_m[i] - b_m[i]) > 1e-12) return false;
  return true;
}

SpectralScene resample_scene_bands(SpectralScene scene, const std::vector<double>& centres_m, double band_width_m,
                                   const std::string& path) {
  if (same_bands(scene.wavelengths_m, centres_m)) return scene;
  const torch::Tensor R = band_resampling_matrix(scene.wavelengths_m, centres_m, band_width_m, path).to(torch::kFloat32);
  log::warn(path + ": " + nm_list(scene.wavelengths_m) + " resampled to the config's " + nm_list(centres_m) +
            " by band integration");
  const int64_t L = scene.spectral.size(0), H = scene.spectral.size(1), W = scene.spectral.size(2);
  scene.spectral = torch::mm(R, scene.spectral.reshape({L, H * W})).view({R.size(0), H, W});
  scene.wavelengths_m = centres_m;
  return scene;
}

}  // namespace hsd::data
