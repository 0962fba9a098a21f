// Fisher-information DOE design (Shechtman et al. 2014, as used by Baek et al.
// 2021 to initialise end-to-end training): minimise the aggregated CRLB
// (fisher.h) over the height map with Adam, in a Zernike basis (Noll modes
// 2.., coefficients in micrometres of height, default) or free-form (one value
// per DOE sample), from the unwrapped Fresnel lens or a flat start. The height
// is wrapped into [0, max height) as the DOE does (doe.h).
#pragma once
#include <functional>
#include <string>
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "optics/fisher.h"

namespace hsd::optics {

struct FisherDesign {
  FisherBasis basis = FisherBasis::zernike;
  torch::Tensor parameters_um;         // Zernike coefficients [K] or free-form height offsets [N, N] (µm)
  torch::Tensor height_m;              // [N, N] float64 on the design grid, wrapped
  std::vector<double> curve;           // aggregated CRLB per step (before the step), then the final value
  double start_aggregate = 0, final_aggregate = 0;
};

// The point-source CRLB settings of a config (fisher.*: photons, background,
// nuisance, aggregate; the grid every wavelength_stride-th band and
// depth_stride-th depth, and the last; aggregation scales from the config's
// layers and band width): hsd_fisher's and hsd_fabricate's.
FisherSettings fisher_settings(const Config& cfg);

// The design grid: the DOE's physical size at fisher.design_samples samples.
OpticsConfig fisher_design_optics(const Config& cfg);

// The unwrapped Fresnel lens (fresnel_height before its wrap) [N, N] float64.
torch::Tensor fresnel_lens_height(int64_t n, double pitch_m, double design_wavelength_m, double design_index,
                                  double design_depth_m, double sensor_distance_m);

// Runs the design on g's grid from start_raw_height_m [N, N] (unwrapped);
// on_step(step, aggregate) reports progress. The objective is crlb_report's
// aggregate (the point-source bound).
FisherDesign design_fisher_doe(const FisherGeometry& g, const Material& material, const FisherSettings& s,
                               const torch::Tensor& start_raw_height_m, double max_height_m, const FisherConfig& cfg,
                               const std::function<void(int64_t, double)>& on_step = {});

// The same with any bound: objective(height [N, N] float64, requires grad)
// returns a report whose aggregate is minimised (e.g. scene_fisher.h's).
using CrlbObjective = std::function<CrlbReport(const torch::Tensor&)>;
FisherDesign design_fisher_doe(const FisherGeometry& g, const CrlbObjective& objective,
                               const torch::Tensor& start_raw_height_m, double max_height_m, const FisherConfig& cfg,
                               const std::function<void(int64_t, double)>& on_step = {});

// The design's height [n, n] (wrapped) on another grid of the same physical
// size: Zernike modes re-evaluated there, free-form offsets resampled
// bilinearly; start_raw_height_m is the start on that grid.
torch::Tensor design_height_on_grid(const FisherDesign& d, const torch::Tensor& start_raw_height_m, int64_t n,
                                    double pitch_m, double aperture_diameter_m, double max_height_m);

}  // namespace hsd::optics
