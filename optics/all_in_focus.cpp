#include "optics/all_in_focus.h"

#include <torch/torch.h>

#include "optics/doe.h"
#include "optics/psf.h"

namespace hsd::optics {

torch::Tensor all_in_focus_psf(const OpticsConfig& cfg, const Material& material, torch::Device device) {
  const double lambda0 = cfg.doe.design_wavelength_m;
  const double z0 = cfg.doe.design_depth_m > 0.0 ? cfg.doe.design_depth_m : middle_depth_m(cfg.depths_m);
  // One band at λ0 (no spectral quadrature) and one depth z0, in float64.
  OpticsConfig one = cfg;
  one.wavelengths_nm = {lambda0 * 1e9};
  one.band_width_nm = 0.0;
  one.spectral_samples = 1;
  one.depths_m = {z0};
  one.precision = FloatPrecision::float64;
  one.pupil_cell_integration = CellIntegration::midpoint;  // an ideal, continuous lens (no cell staircase)
  const PsfSimulator sim(make_psf_spec(one, material, torch::kCPU));
  const torch::Tensor h = fresnel_height(cfg.doe_samples, cfg.doe_pitch_m, lambda0, material.index(lambda0), z0,
                                         cfg.sensor_distance_m);
  const torch::Tensor p = sim.compute(h).psf[0][0];  // [P, P], sums to 1
  const int64_t L = int64_t(cfg.wavelengths_nm.size()), Z = int64_t(cfg.depths_m.size());
  return p.to(torch::kFloat32).expand({L, Z, p.size(0), p.size(1)}).contiguous().to(device);
}

}  // namespace hsd::optics
