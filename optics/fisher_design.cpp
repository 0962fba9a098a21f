#include "optics/fisher_design.h"

#include <cmath>

#include <torch/torch.h>

#include "common/error.h"
#include "optics/aperture.h"
#include "optics/zernike.h"

namespace hsd::optics {

namespace {
std::vector<double> strided(const std::vector<double>& v, int64_t stride) {
  std::vector<double> out;
  for (size_t i = 0; i < v.size(); i += size_t(stride)) out.push_back(v[i]);
  if (out.back() != v.back()) out.push_back(v.back());
  return out;
}
}  // namespace

FisherSettings fisher_settings(const Config& cfg) {
  const auto& F = cfg.fisher;
  FisherSettings s;
  s.photons = F.photons, s.background = F.background;
  s.wavelengths_nm = strided(cfg.optics.wavelengths_nm, F.wavelength_stride);
  s.depths_m = strided(cfg.optics.depths_m, F.depth_stride);
  const auto& zs = cfg.optics.depths_m;
  s.inv_depth_spacing = zs.size() > 1 ? std::fabs(1.0 / zs.front() - 1.0 / zs.back()) / double(zs.size() - 1) : 1.0;
  s.band_width_nm = cfg.optics.band_width_m() * 1e9;
  s.nuisance = F.nuisance, s.aggregate = F.aggregate, s.aggregate_cap = F.aggregate_cap;
  return s;
}

OpticsConfig fisher_design_optics(const Config& cfg) {
  OpticsConfig design = cfg.optics;
  if (cfg.fisher.design_samples > 0) {
    design.doe_pitch_m = cfg.optics.doe_pitch_m * double(cfg.optics.doe_samples) / double(cfg.fisher.design_samples);
    design.doe_samples = cfg.fisher.design_samples;
  }
  return design;
}

namespace F = torch::nn::functional;

torch::Tensor fresnel_lens_height(int64_t n, double pitch_m, double design_wavelength_m, double design_index,
                                  double design_depth_m, double sensor_distance_m) {
  // fresnel_height (doe.cpp) before its wrap: phase −k r² (1/z0 + 1/s)/2 over k (η − 1).
  const torch::Tensor x = centred_coordinates(n, pitch_m).to(torch::kFloat64);
  const torch::Tensor r2 = x.view({1, -1}).pow(2) + x.view({-1, 1}).pow(2);
  return r2 * (-0.5 * (1.0 / design_depth_m + 1.0 / sensor_distance_m) / (design_index - 1.0));
}

namespace {
torch::Tensor wrap_height(const torch::Tensor& raw, double max_height_m) {
  return torch::remainder(raw, max_height_m);  // gradient 1 almost everywhere
}
}  // namespace

FisherDesign design_fisher_doe(const FisherGeometry& g, const Material& material, const FisherSettings& s,
                               const torch::Tensor& start_raw_height_m, double max_height_m, const FisherConfig& cfg,
                               const std::function<void(int64_t, double)>& on_step) {
  return design_fisher_doe(
      g, [&](const torch::Tensor& h) { return crlb_report(g, material, h, s); }, start_raw_height_m, max_height_m, cfg,
      on_step);
}

FisherDesign design_fisher_doe(const FisherGeometry& g, const CrlbObjective& objective,
                               const torch::Tensor& start_raw_height_m, double max_height_m, const FisherConfig& cfg,
                               const std::function<void(int64_t, double)>& on_step) {
  if (!(max_height_m > 0)) throw InputError("Fisher design: the maximum height must be > 0");
  FisherDesign d;
  d.basis = cfg.basis;
  torch::Tensor basis;
  if (cfg.basis == FisherBasis::zernike) {
    basis = zernike_basis(2, cfg.zernike_modes, g.doe_samples, g.doe_pitch_m, g.aperture_diameter_m);  // [K, N, N]
    d.parameters_um = torch::zeros({cfg.zernike_modes}, torch::kFloat64);
  } else {
    d.parameters_um = torch::zeros({g.doe_samples, g.doe_samples}, torch::kFloat64);
  }
  d.parameters_um.set_requires_grad(true);
  auto height = [&] {
    const torch::Tensor delta = cfg.basis == FisherBasis::zernike
                                    ? torch::tensordot(d.parameters_um, basis, {0}, {0})
                                    : d.parameters_um;
    return wrap_height(start_raw_height_m + 1e-6 * delta, max_height_m);
  };
  torch::optim::Adam opt({d.parameters_um}, torch::optim::AdamOptions(cfg.lr));
  for (int64_t k = 0; k <= cfg.steps; ++k) {
    const CrlbReport r = objective(height());
    const double a = r.aggregate.item<double>();
    if (!std::isfinite(a)) throw NumericalError("Fisher design step " + std::to_string(k) + ": the aggregated CRLB is not finite");
    d.curve.push_back(a);
    if (k == 0) d.start_aggregate = a;
    if (on_step) on_step(k, a);
    if (k == cfg.steps) break;
    opt.zero_grad();
    r.aggregate.backward();
    if (!torch::isfinite(d.parameters_um.grad()).all().item<bool>())
      throw NumericalError("Fisher design step " + std::to_string(k) + ": the gradient of the design parameters holds NaN or Inf");
    opt.step();
  }
  d.final_aggregate = d.curve.back();
  d.height_m = height().detach();
  d.parameters_um = d.parameters_um.detach();
  return d;
}

torch::Tensor design_height_on_grid(const FisherDesign& d, const torch::Tensor& start_raw_height_m, int64_t n,
                                    double pitch_m, double aperture_diameter_m, double max_height_m) {
  torch::Tensor delta;
  if (d.basis == FisherBasis::zernike) {
    const torch::Tensor basis = zernike_basis(2, d.parameters_um.size(0), n, pitch_m, aperture_diameter_m);
    delta = torch::tensordot(d.parameters_um, basis, {0}, {0});
  } else {
    delta = F::interpolate(d.parameters_um.view({1, 1, d.parameters_um.size(0), d.parameters_um.size(1)}),
                           F::InterpolateFuncOptions().size(std::vector<int64_t>{n, n}).mode(torch::kBilinear).align_corners(false))
                .view({n, n});
  }
  return wrap_height(start_raw_height_m + 1e-6 * delta, max_height_m);
}

}  // namespace hsd::optics
