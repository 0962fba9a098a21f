#include "viz/psf_atlas.h"

#include <cmath>
#include <cstdio>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "optics/spectrum.h"

namespace hsd::viz {

torch::Tensor render_psf_atlas(const torch::Tensor& psf_in, const std::vector<double>& wavelengths_m,
                               const std::vector<double>& depths_m) {
  const torch::Tensor psf = psf_in.detach().cpu().to(torch::kFloat64);
  const int L = int(psf.size(0)), Z = int(psf.size(1)), P = int(psf.size(2));
  const int scale = std::max(1, int(std::ceil(72.0 / P)));
  const int tile = P * scale, gap = 2, left = 70, top = 40;
  const int W = left + Z * (tile + gap), H = top + L * (tile + gap);
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(24, 24, 24));
  const auto font = cv::FONT_HERSHEY_SIMPLEX;
  for (int z = 0; z < Z; ++z) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3g m", depths_m[size_t(z)]);
    cv::putText(img, buf, cv::Point(left + z * (tile + gap) + 4, top - 12), font, 0.4, cv::Scalar(230, 230, 230), 1,
                cv::LINE_AA);
  }
  for (int l = 0; l < L; ++l) {
    const auto rgb = optics::wavelength_display_rgb(wavelengths_m[size_t(l)]);
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.0f nm", wavelengths_m[size_t(l)] * 1e9);
    const int y0 = top + l * (tile + gap);
    cv::putText(img, buf, cv::Point(6, y0 + tile / 2 + 4), font, 0.4,
                cv::Scalar(40 + 215 * rgb[2], 40 + 215 * rgb[1], 40 + 215 * rgb[0]), 1, cv::LINE_AA);
    for (int z = 0; z < Z; ++z) {
      const torch::Tensor t = psf[l][z];
      const double peak = std::max(t.max().item<double>(), 1e-300);
      const torch::Tensor v = (t / peak).clamp(0.0, 1.0).sqrt().contiguous();
      auto a = v.accessor<double, 2>();
      cv::Mat small(P, P, CV_8UC3);
      for (int i = 0; i < P; ++i)
        for (int j = 0; j < P; ++j)
          small.at<cv::Vec3b>(i, j) = cv::Vec3b(cv::saturate_cast<uchar>(255.0 * a[i][j] * rgb[2]),
                                                cv::saturate_cast<uchar>(255.0 * a[i][j] * rgb[1]),
                                                cv::saturate_cast<uchar>(255.0 * a[i][j] * rgb[0]));
      cv::Mat big;
      cv::resize(small, big, cv::Size(tile, tile), 0, 0, cv::INTER_NEAREST);
      big.copyTo(img(cv::Rect(left + z * (tile + gap), y0, tile, tile)));
    }
  }
  return torch::from_blob(img.data, {H, W, 3}, torch::kUInt8).clone();
}

void write_psf_atlas(const std::string& path, const torch::Tensor& psf, const std::vector<double>& wavelengths_m,
                     const std::vector<double>& depths_m) {
  torch::Tensor t = render_psf_atlas(psf, wavelengths_m, depths_m).contiguous();
  cv::Mat img(int(t.size(0)), int(t.size(1)), CV_8UC3, t.data_ptr<uint8_t>());
  std::vector<uchar> buf;
  if (!cv::imencode(".png", img, buf)) input_error(path, "PNG encoding failed");
  write_binary_file(path, std::vector<char>(buf.begin(), buf.end()));  // temp file + rename
}

}  // namespace hsd::viz
