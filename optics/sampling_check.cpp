#include "optics/sampling_check.h"

#include <cmath>
#include <cstdio>

#include <torch/torch.h>

#include "optics/aperture.h"
#include "optics/fresnel_mft.h"

namespace hsd::optics {

namespace {
std::string fmt(const char* f, double a, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c, d);
  return buf;
}
}  // namespace

SamplingReport check_sampling(const PsfSpec& spec, const torch::Tensor& aperture, const torch::Tensor& height_m,
                              const torch::Tensor& energy_in_window, double energy_warn_threshold) {
  SamplingReport r;
  const int64_t L = int64_t(spec.wavelengths_m.size()), Z = int64_t(spec.depths_m.size());
  r.max_phase_step_rad = torch::zeros({L, Z}, torch::kFloat64);
  const double delta = spec.doe_pitch_m, s = spec.sensor_distance_m;
  const torch::Tensor A = aperture.detach().cpu().to(torch::kFloat64);
  const torch::Tensor h = height_m.detach().cpu().to(torch::kFloat64);
  const torch::Tensor x = centred_coordinates(spec.doe_samples, delta);
  // Neighbour pairs that both carry light.
  const torch::Tensor lit = A > 0;
  const torch::Tensor pair_x = lit.narrow(1, 0, lit.size(1) - 1) & lit.narrow(1, 1, lit.size(1) - 1);
  const torch::Tensor pair_y = lit.narrow(0, 0, lit.size(0) - 1) & lit.narrow(0, 1, lit.size(0) - 1);
  // ξ_{j+1}² − ξ_j² along x (depends on the column), same along y (row).
  const torch::Tensor dx2 = (x.narrow(0, 1, x.size(0) - 1).pow(2) - x.narrow(0, 0, x.size(0) - 1).pow(2));
  const double window_edge = 0.5 * double(spec.psf_size) * spec.pixel_pitch_m;
  auto acc = r.max_phase_step_rad.accessor<double, 2>();
  for (int64_t l = 0; l < L; ++l) {
    const double lam = spec.wavelengths_m[size_t(l)];
    const double k = 2.0 * M_PI / lam;
    const torch::Tensor phi = h * (k * (spec.refractive_index[size_t(l)] - 1.0));
    const torch::Tensor dphi_x = wrap_phase(phi.narrow(1, 1, phi.size(1) - 1) - phi.narrow(1, 0, phi.size(1) - 1));
    const torch::Tensor dphi_y = wrap_phase(phi.narrow(0, 1, phi.size(0) - 1) - phi.narrow(0, 0, phi.size(0) - 1));
    const double tilt = k * delta * window_edge / s;
    for (int64_t z = 0; z < Z; ++z) {
      const double c = 0.5 * k * (1.0 / spec.depths_m[size_t(z)] + 1.0 / s);
      const torch::Tensor sx = (dphi_x + (dx2 * c).view({1, -1})).abs().masked_fill(~pair_x, 0.0);
      const torch::Tensor sy = (dphi_y + (dx2 * c).view({-1, 1})).abs().masked_fill(~pair_y, 0.0);
      const double step = std::max(sx.max().item<double>(), sy.max().item<double>()) + tilt;
      acc[l][z] = step;
      if (step > M_PI)
        r.warnings.push_back(fmt("pupil undersampled at lambda = %.0f nm, z = %.4g m: phase step %.2f rad between "
                                 "neighbouring DOE samples (> pi); reduce optics.doe_pitch_m or raise the depth",
                                 lam * 1e9, spec.depths_m[size_t(z)], step));
    }
    const double period = lam * s / (delta * spec.pixel_pitch_m);
    r.period_pixels.push_back(period);
    if (period < double(spec.psf_size))
      r.warnings.push_back(fmt("DOE grid aliasing at lambda = %.0f nm: the sampled pupil repeats the PSF every %.1f "
                               "pixels, less than the %.0f-pixel window; reduce optics.doe_pitch_m",
                               lam * 1e9, period, double(spec.psf_size)));
  }
  if (energy_in_window.defined()) {
    const torch::Tensor e = energy_in_window.detach().cpu().to(torch::kFloat64);
    auto ea = e.accessor<double, 2>();
    for (int64_t l = 0; l < e.size(0); ++l)
      for (int64_t z = 0; z < e.size(1); ++z)
        if (ea[l][z] < energy_warn_threshold)
          r.warnings.push_back(fmt("only %.1f%% of the light reaches the %.0f-pixel window at lambda = %.0f nm, "
                                   "z = %.4g m (optics.energy_warn_threshold); consider a larger optics.psf_size",
                                   100.0 * ea[l][z], double(spec.psf_size), spec.wavelengths_m[size_t(l)] * 1e9,
                                   spec.depths_m[size_t(z)]));
  }
  return r;
}

}  // namespace hsd::optics
