#include "optics/sampling_check.h"

#include <cmath>
#include <cstdio>

#include <torch/torch.h>

#include "common/text_format.h"

namespace hsd::optics {

SamplingReport check_sampling(const PsfSpec& spec, const torch::Tensor& energy_in_window, double energy_warn_threshold) {
  SamplingReport r;
  const int64_t L = int64_t(spec.wavelengths_m.size()), Z = int64_t(spec.depths_m.size());
  r.max_phase_step_rad = torch::zeros({L, Z}, torch::kFloat64);
  const double delta = spec.pupil_pitch_m(), s = spec.sensor_distance_m;  // δ/k with pupil oversampling
  // Largest |ξ| of a lit sample along an axis: the aperture's half width (plus the edge cell).
  const double half_width = std::min(0.5 * spec.aperture_diameter_m + 0.5 * delta, 0.5 * double(spec.pupil_samples()) * delta);
  const double window_edge = 0.5 * double(spec.psf_size) * spec.pixel_pitch_m;
  auto acc = r.max_phase_step_rad.accessor<double, 2>();
  for (int64_t l = 0; l < L; ++l) {
    const double lam = spec.wavelengths_m[size_t(l)];
    const double k = 2.0 * M_PI / lam;
    for (int64_t z = 0; z < Z; ++z) {
      const double curvature = std::fabs(1.0 / spec.depths_m[size_t(z)] + 1.0 / s);
      const double step = k * delta * (half_width * curvature + window_edge / s);
      acc[l][z] = step;
      if (step > M_PI)
        r.warnings.push_back(format("pupil undersampled at lambda = %.0f nm, z = %.4g m: phase step %.2f rad between "
                                 "neighbouring pupil samples (> pi); raise optics.pupil_oversampling",
                                 lam * 1e9, spec.depths_m[size_t(z)], step));
    }
    // The cross term of the cell integration is first order in the tilt's phase
    // ramp across a cell, B = k x δ/(2s); at the window edge it must stay small.
    const double b_edge = M_PI * double(spec.psf_size) * spec.pixel_pitch_m * delta / (2.0 * lam * s);
    if (spec.cell_sinc() && b_edge > 0.5)
      r.warnings.push_back(format("cell integration at lambda = %.0f nm: the tilt's phase ramp across a pupil cell reaches "
                               "%.2f rad at the window edge (its expansion assumes << 1); raise optics.pupil_oversampling",
                               lam * 1e9, b_edge));
    const double period = lam * s / (delta * spec.pixel_pitch_m);
    r.period_pixels.push_back(period);
    if (period < double(spec.psf_size))
      r.warnings.push_back(format("DOE grid aliasing at lambda = %.0f nm: the sampled pupil repeats the PSF every %.1f "
                               "pixels, less than the %.0f-pixel window; raise optics.pupil_oversampling",
                               lam * 1e9, period, double(spec.psf_size)));
  }
  if (energy_in_window.defined()) {
    const torch::Tensor e = energy_in_window.detach().cpu().to(torch::kFloat64);
    auto ea = e.accessor<double, 2>();
    for (int64_t l = 0; l < e.size(0); ++l)
      for (int64_t z = 0; z < e.size(1); ++z)
        if (ea[l][z] < energy_warn_threshold)
          r.warnings.push_back(format("only %.1f%% of the light reaches the %.0f-pixel window at lambda = %.0f nm, "
                                   "z = %.4g m (optics.energy_warn_threshold); consider a larger optics.psf_size",
                                   100.0 * ea[l][z], double(spec.psf_size), spec.wavelengths_m[size_t(l)] * 1e9,
                                   spec.depths_m[size_t(z)]));
  }
  return r;
}

}  // namespace hsd::optics
