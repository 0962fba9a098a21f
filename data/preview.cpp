#include "data/preview.h"

#include <array>
#include <cmath>
#include <cstdio>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "optics/spectrum.h"

namespace hsd::data {

torch::Tensor cmf_bands(const std::vector<double>& wavelengths_m, double band_width_m) {
  static const optics::SpectralTable cmf = optics::SpectralTable::load_csv(optics::spectra_path("cie1931_2deg_cmf.csv"));
  const double half_nm = 0.5 * band_width_m * 1e9;
  torch::Tensor out = torch::empty({3, int64_t(wavelengths_m.size())}, torch::kFloat64);
  const std::array<const char*, 3> cols{"x_bar", "y_bar", "z_bar"};
  for (int64_t c = 0; c < 3; ++c)
    for (size_t l = 0; l < wavelengths_m.size(); ++l)
      out[c][int64_t(l)] = cmf.band_mean(cols[size_t(c)], wavelengths_m[l] * 1e9 - half_nm, wavelengths_m[l] * 1e9 + half_nm);
  return out;
}

torch::Tensor spectral_to_linear_srgb(const torch::Tensor& spectral, const std::vector<double>& wavelengths_m,
                                      double band_width_m, const torch::Tensor& illuminant, bool clip_negative) {
  const int64_t L = spectral.size(0), H = spectral.size(1), W = spectral.size(2);
  torch::Tensor cmf = cmf_bands(wavelengths_m, band_width_m);  // [3, L]
  if (illuminant.defined()) cmf = cmf * illuminant.to(torch::kFloat64).view({1, L});
  const double white_y = cmf[1].sum().item<double>();
  if (!(white_y > 0.0)) throw InputError("sRGB preview: the bands see no luminance");
  const torch::Tensor xyz = torch::mm(cmf / white_y, spectral.to(torch::kFloat64).reshape({L, H * W}));
  const torch::Tensor M = torch::tensor({3.2406, -1.5372, -0.4986, -0.9689, 1.8758, 0.0415, 0.0557, -0.2040, 1.0570},
                                        torch::kFloat64).view({3, 3});
  const torch::Tensor rgb = torch::mm(M, xyz).view({3, H, W});
  return (clip_negative ? rgb.clamp_min(0.0) : rgb).to(torch::kFloat32);
}

void write_depth_png(const std::string& path, const torch::Tensor& depth_m, const torch::Tensor& mask, double near_m,
                     double far_m) {
  const torch::Tensor d = depth_m.detach().to(torch::kFloat64).cpu().reshape({depth_m.size(-2), depth_m.size(-1)});
  const int64_t H = d.size(0), W = d.size(1);
  const double lo = 1.0 / far_m, hi = far_m > near_m ? 1.0 / near_m : lo + 1e-9;  // guarded
  const torch::Tensor v = ((1.0 / d.clamp_min(1e-9) - lo) / (hi - lo)).clamp(0.0, 1.0);  // 1 = near
  const torch::Tensor g8 = (v * 255.0 + 0.5).to(torch::kUInt8).contiguous();
  cv::Mat grey(int(H), int(W), CV_8UC1, g8.data_ptr<uint8_t>());
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  if (mask.defined()) {
    const torch::Tensor m = (mask.detach().cpu().reshape({H, W}) < 0.5).to(torch::kUInt8).contiguous();
    cv::Mat invalid(int(H), int(W), CV_8UC1, m.data_ptr<uint8_t>());
    colour.setTo(cv::Scalar(0, 0, 0), invalid);
  }
  // Colour bar: 16 px wide, near at the top, labels every quarter in metres.
  const int bar_w = 16, label_w = 64, pad = 6;
  cv::Mat canvas(int(H), int(W) + pad + bar_w + label_w, CV_8UC3, cv::Scalar(255, 255, 255));
  colour.copyTo(canvas(cv::Rect(0, 0, int(W), int(H))));
  cv::Mat ramp(int(H), 1, CV_8UC1);
  for (int y = 0; y < int(H); ++y) ramp.at<uchar>(y, 0) = cv::saturate_cast<uchar>(255.0 * (1.0 - double(y) / double(std::max<int64_t>(H - 1, 1))));
  cv::Mat ramp_c;
  cv::applyColorMap(ramp, ramp_c, cv::COLORMAP_TURBO);
  cv::resize(ramp_c, ramp_c, cv::Size(bar_w, int(H)), 0, 0, cv::INTER_NEAREST);
  ramp_c.copyTo(canvas(cv::Rect(int(W) + pad, 0, bar_w, int(H))));
  const double font = std::max(0.3, std::min(0.5, double(H) / 600.0));
  for (int k = 0; k <= 4; ++k) {
    const double f = double(k) / 4.0;  // 0 = top (near)
    const double inv = hi - f * (hi - lo);
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.2f m", 1.0 / inv);
    const int y = std::max(10, std::min(int(f * double(H - 1)) + 4, int(H) - 2));
    cv::putText(canvas, buf, cv::Point(int(W) + pad + bar_w + 3, y), cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), 1,
                cv::LINE_AA);
  }
  std::vector<uchar> buf;
  if (!cv::imencode(".png", canvas, buf)) input_error(path, "PNG encoding failed");
  write_binary_file(path, std::vector<char>(buf.begin(), buf.end()));
}

}  // namespace hsd::data
