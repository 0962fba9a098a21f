#include "data/rgbd_import.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/torch.h>

#include "common/error.h"
#include "data/image_io.h"
#include "data/preview.h"
#include "optics/spectrum.h"

namespace hsd::data {

torch::Tensor lift_srgb_to_reflectance(const torch::Tensor& linear_srgb, const ReflectanceLibrary& lib,
                                       const std::vector<double>& wavelengths_m, double band_width_m) {
  const int64_t L = int64_t(wavelengths_m.size()), H = linear_srgb.size(1), W = linear_srgb.size(2);
  const torch::Tensor d65 = optics::illuminant_bands("D65", wavelengths_m, band_width_m).to(torch::kFloat64);
  // M [3, L]: reflectance -> linear sRGB under D65 (white -> Y = 1), as the preview renders it.
  const torch::Tensor eye = torch::eye(L, torch::kFloat64).view({L, L, 1});
  const torch::Tensor M = spectral_to_linear_srgb(eye, wavelengths_m, band_width_m, d65, false).to(torch::kFloat64).view({3, L});
  const torch::Tensor B = lib.basis().narrow(0, 0, std::min<int64_t>(3, lib.basis().size(0)));  // [3, L]
  if (L < 3 || B.size(0) < 3)
    input_error("config key optics.wavelengths_nm", "lifting RGB to spectra needs at least 3 bands");
  const torch::Tensor A = torch::mm(M, B.t());                                                 // [3, 3]
  const torch::Tensor sv = torch::linalg_svdvals(A);
  if (!(sv.min().item<double>() > 1e-6 * sv.max().item<double>()))
    input_error("config key optics.wavelengths_nm", "these bands cannot tell R, G and B apart (the lifting is singular)");
  const torch::Tensor rhs = linear_srgb.to(torch::kFloat64).reshape({3, H * W}) - torch::mv(M, lib.mean()).view({3, 1});
  const torch::Tensor coef = torch::linalg_solve(A, rhs);                                      // [3, H·W]
  return (lib.mean().view({L, 1}) + torch::mm(B.t(), coef)).clamp(0.0, 1.0).view({L, H, W}).to(torch::kFloat32);
}

SpectralScene import_rgbd(const RgbdImport& in, const ReflectanceLibrary& lib, const std::vector<double>& wavelengths_m,
                          double band_width_m, std::string* notes) {
  cv::Mat bgr = read_image(in.rgb_path, cv::IMREAD_COLOR, "--rgb");
  cv::Mat disp = read_image(in.disparity_path, cv::IMREAD_UNCHANGED, "--disparity");
  if (disp.channels() != 1) input_error(in.disparity_path, "disparity must be a single-channel (grey) image");
  if (disp.depth() != CV_8U && disp.depth() != CV_16U) input_error(in.disparity_path, "disparity must be 8- or 16-bit");
  if (bgr.size() != disp.size())
    input_error(in.disparity_path, "is " + std::to_string(disp.cols) + "x" + std::to_string(disp.rows) + " but " +
                                       in.rgb_path + " is " + std::to_string(bgr.cols) + "x" + std::to_string(bgr.rows));
  if (!(in.scale > 0.0 && in.scale <= 1.0)) input_error("--scale", "must be in (0, 1]");
  if (!(in.near_m > 0.0 && in.far_m > in.near_m)) input_error("--near-m/--far-m", "need 0 < near < far");
  cv::Mat d32;
  disp.convertTo(d32, CV_32F);
  if (in.scale < 1.0) {
    const cv::Size sz(std::max(1, int(std::lround(bgr.cols * in.scale))), std::max(1, int(std::lround(bgr.rows * in.scale))));
    cv::resize(bgr, bgr, sz, 0, 0, cv::INTER_AREA);
    cv::resize(d32, d32, sz, 0, 0, cv::INTER_NEAREST);  // do not blend unknown (0) into known disparities
    d32 *= float(in.scale);                              // disparity in pixels of the new size
  }
  const int64_t H = bgr.rows, W = bgr.cols;
  const torch::Tensor rgb8 = torch::from_blob(bgr.data, {H, W, 3}, torch::kUInt8).clone().flip(2).permute({2, 0, 1});
  const torch::Tensor v = srgb_to_linear(rgb8.to(torch::kFloat64) / 255.0);
  SpectralScene s;
  s.wavelengths_m = wavelengths_m;
  s.kind = SpectralKind::Reflectance;
  s.spectral = lift_srgb_to_reflectance(v, lib, wavelengths_m, band_width_m);
  const torch::Tensor d = torch::from_blob(d32.data, {H, W}, torch::kFloat32).clone().to(torch::kFloat64);
  torch::Tensor known = d > 0;
  if (!known.any().item<bool>()) input_error(in.disparity_path, "has no known disparity (all 0)");
  if (in.focal_px > 0.0) {
    known = known & (d + in.doffs_px * in.scale > 0);  // a bad calibration: no depth there
    if (!known.any().item<bool>())
      input_error("--doffs-px", "d + doffs <= 0 at every known pixel of " + in.disparity_path + " (no positive depth; check the calibration)");
  }
  torch::Tensor z;
  char buf[320];
  if (in.focal_px > 0.0) {
    const double f = in.focal_px * in.scale, doffs = in.doffs_px * in.scale;
    z = f * in.baseline_m / (d + doffs).clamp_min(1e-9);
    std::snprintf(buf, sizeof buf, "calibrated: Z = f B / (d + doffs), f = %.1f px, B = %.4f m, doffs = %.1f px", f, in.baseline_m, doffs);
  } else {
    const double dlo = d.masked_select(known).min().item<double>(), dhi = d.masked_select(known).max().item<double>();
    const double span = std::max(dhi - dlo, 1e-9);
    z = 1.0 / (1.0 / in.far_m + (d - dlo) / span * (1.0 / in.near_m - 1.0 / in.far_m));
    std::snprintf(buf, sizeof buf, "uncalibrated: disparity %.1f-%.1f px mapped linearly in 1/Z onto %.2f-%.2f m", dlo, dhi,
                  in.far_m, in.near_m);
  }
  z = torch::where(known, z, torch::full_like(z, in.far_m));
  s.depth_m = z.to(torch::kFloat32).unsqueeze(0);
  s.mask = known.to(torch::kFloat32).unsqueeze(0);
  if (notes) {
    char head[200];
    std::snprintf(head, sizeof head, "real RGB-D import (%lldx%lld): RGB lifted to spectra with the ColorChecker model (not measured spectra); %.1f %% unknown depth; ",
                  (long long)W, (long long)H, 100.0 * (1.0 - known.to(torch::kFloat64).mean().item<double>()));
    *notes = std::string(head) + buf + "; sources: " + std::filesystem::path(in.rgb_path).filename().string() + ", " +
             std::filesystem::path(in.disparity_path).filename().string();
  }
  return s;
}

}  // namespace hsd::data
