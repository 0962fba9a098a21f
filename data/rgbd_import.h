// Real RGB-D pictures to spectral scenes: an 8-bit sRGB photograph is lifted
// to reflectance spectra (per pixel, the point of the ColorChecker linear
// model — mean + 3 principal components — whose sRGB rendering under D65
// matches the pixel, clipped to [0, 1]: plausible smooth spectra, not measured
// ones), and a disparity map (8- or 16-bit PNG, 0 = unknown) becomes Z:
//   calibrated:   Z = f·B / (d + doffs)          (Middlebury convention)
//   uncalibrated: 1/Z linear in d over [1/far, 1/near] (the disparity's own
//                 range mapped onto the depth range; Middlebury 2006 ships
//                 without its dmin offset, so metric depth is unknown there)
// Unknown disparities are masked invalid.
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

#include "data/reflectance_library.h"
#include "data/scene_exr.h"

namespace hsd::data {

struct RgbdImport {
  std::string rgb_path, disparity_path;
  double near_m = 0.4, far_m = 2.5;                      // uncalibrated mapping
  double focal_px = 0.0, baseline_m = 0.0, doffs_px = 0.0;  // calibrated when focal_px > 0 (full-size pixels)
  double scale = 1.0;                                    // resize factor for both images
};

// linear sRGB [3, H, W] -> reflectance [L, H, W] in [0, 1] (see above).
torch::Tensor lift_srgb_to_reflectance(const torch::Tensor& linear_srgb, const ReflectanceLibrary& lib,
                                       const std::vector<double>& wavelengths_m, double band_width_m);

// The scene (reflectance); `notes` receives one line on what was done.
// InputError naming the file for unreadable images or mismatched sizes.
SpectralScene import_rgbd(const RgbdImport& in, const ReflectanceLibrary& lib, const std::vector<double>& wavelengths_m,
                          double band_width_m, std::string* notes);

}  // namespace hsd::data
