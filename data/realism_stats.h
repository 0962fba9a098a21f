// How much a spectral scene looks like real data, as numbers (hsd_scenes,
// hsd_bench data). A network learns depth from how the PSF blurs texture and
// spectra from spectral detail RGB does not explain, so the statistics are:
//   * textured fraction: valid pixels within `radius_px` (8) of a luminance
//     gradient above `rel_threshold` (2 %) of the scene's mean luminance
//     (forward differences between valid neighbours; Euclidean distance);
//   * power-spectrum slope: the slope of log P(f) against log f, P the radially
//     averaged power spectrum of the luminance (invalid pixels set to the valid
//     mean, mean removed, 2-D Hann window), f from 4 cycles per image to
//     0.4 cycles per pixel in 16 log-spaced bins. White noise: 0; natural
//     images: about -2 (Field 1987, JOSA A 4(12); van der Schaaf & van Hateren
//     1996: -1.88 ± 0.43);
//   * principal components for 99 % of the spectral variance (centred PCA of
//     the valid pixels' spectra);
//   * RGB-unexplained residual: ‖S − C·M‖_F / ‖S‖_F for the best linear map M
//     (least squares, no offset) from the camera's RGB C [N, 3] to the spectra
//     S [N, L]: 0 when every spectrum is a linear function of its RGB, as with
//     one spectrum per colour (RGB lifting);
//   * depth histogram: the valid pixels' fractions in equal bins of inverse
//     depth over [1/far, 1/near] (values outside go to the end bins);
//   * depth structure: how fine the depth map is at a fifth of the image's
//     smaller side (data/depth_structure.h), compared with real depth maps.
// Luminance is CIE Y under D65 (white = 1) and RGB the camera response under
// D65, for reflectance scenes; for radiance scenes the illuminant is 1.
#pragma once
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <torch/types.h>

#include "common/json_reader.h"
#include "data/scene_exr.h"

namespace hsd::data {

// lum [H, W] float64, valid [H, W] bool. Fraction in [0, 1] (0 with no valid pixel).
double textured_fraction(const torch::Tensor& lum, const torch::Tensor& valid, double radius_px = 8.0,
                         double rel_threshold = 0.02);
// lum [H, W], valid [H, W] bool (empty tensor = all valid). H, W >= 16.
double power_spectrum_slope(const torch::Tensor& lum, const torch::Tensor& valid = {});
// spectra [N, L]. The smallest k whose leading eigenvalues hold `fraction` of the variance.
int64_t principal_components_for(const torch::Tensor& spectra, double fraction = 0.99);
// rgb [N, 3], spectra [N, L]. See above.
double rgb_unexplained_residual(const torch::Tensor& rgb, const torch::Tensor& spectra);
// depth [H, W] metres, valid [H, W] bool: `bins` fractions summing to 1 (zeros with no valid pixel).
std::vector<double> inverse_depth_histogram(const torch::Tensor& depth_m, const torch::Tensor& valid, double near_m,
                                            double far_m, int64_t bins);

struct RealismSpec {
  std::vector<double> wavelengths_m;
  double band_width_m = 10e-9;
  std::string camera = "canon_5d_mark_iii";
  double near_m = 0.4, far_m = 2.5;  // the depth histogram's range
  int64_t depth_bins = 8;            // a multiple of 4 (quarters are reported too)
  // Band weights (filled by with_band_weights; measure_realism computes them when empty):
  torch::Tensor ybar{}, camera_rgb{}, d65{};  // CIE ȳ [L], camera response [3, L], D65 [L], float64
};
// The spec with its band weights computed once (one read of the tables for many scenes).
RealismSpec with_band_weights(RealismSpec spec);

struct SceneRealism {
  std::string name;
  int64_t valid_pixels = 0;
  double textured_fraction = 0, psd_slope = 0, rgb_unexplained = 0;
  int64_t pcs_99 = 0;
  std::vector<double> inv_depth_hist;      // depth_bins fractions, near end last (1/far .. 1/near)
  std::vector<double> inv_depth_quarters;  // the same in four quarters
  double depth_structure = std::nan("");   // depth_structure.h (NaN without depth)
  bool has_depth = true;
};

// Per-scene statistics (scene on spec.wavelengths_m). `has_depth` false skips the histogram.
SceneRealism measure_realism(const SpectralScene& scene, const RealismSpec& spec, const std::string& name,
                             bool has_depth = true);

struct RealismSummary {
  std::vector<SceneRealism> scenes;
  SceneRealism mean;  // means over scenes; the histogram pools all valid pixels
};
RealismSummary summarise_realism(std::vector<SceneRealism> scenes);

// The targets of the realistic generator (docs/data.md): textured >= 0.95,
// slope in [-2.3, -1.7], RGB-unexplained >= 0.07, every inverse-depth quarter >= 15 %.
struct RealismTargets {
  double textured_min = 0.95, slope_lo = -2.3, slope_hi = -1.7, rgb_unexplained_min = 0.07, quarter_min = 0.15;
};
// One line per target with "met" / "NOT met".
std::vector<std::string> check_realism(const SceneRealism& mean, const RealismTargets& t = {});

Json realism_json(const RealismSummary& s, const SceneRealism* reference);
// A Markdown table: one row per scene, the mean, and the reference (when given).
std::string realism_markdown(const RealismSummary& s, const SceneRealism* reference);

}  // namespace hsd::data
