#include "data/depth_structure.h"

#include <cmath>
#include <fstream>
#include <iterator>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/torch.h>

#include "common/error.h"
#include "data/image_io.h"
#include "optics/spectrum.h"

namespace hsd::data {

namespace F = torch::nn::functional;

torch::Tensor box_oracle_depth_map(const torch::Tensor& depth_m, const torch::Tensor& mask, int64_t window_px) {
  if (window_px < 1 || window_px % 2 == 0) throw InputError("resolution oracle: the window must be odd and >= 1");
  if (depth_m.dim() < 2 || !mask.sizes().equals(depth_m.sizes()))
    throw InputError("resolution oracle: depth and mask must be [.., H, W] of the same shape, got " +
                     c10::str(depth_m.sizes()) + " and " + c10::str(mask.sizes()));
  const int64_t H = depth_m.size(-2), W = depth_m.size(-1), w = window_px;
  const torch::Tensor z = depth_m.to(torch::kFloat64).reshape({-1, 1, H, W});
  const torch::Tensor v = ((mask.reshape({-1, 1, H, W}) > 0.5) & torch::isfinite(z) & (z > 0)).to(torch::kFloat64);
  const torch::Tensor inv = torch::where(v > 0, 1.0 / z, torch::zeros_like(z));
  // Box sums as two 1-D means (zero padding: the box is clipped at the borders; the ratio below cancels the count).
  auto box = [&](const torch::Tensor& x) {
    const torch::Tensor y = F::avg_pool2d(x, F::AvgPool2dFuncOptions({w, 1}).stride(1).padding({w / 2, 0}).count_include_pad(true));
    return F::avg_pool2d(y, F::AvgPool2dFuncOptions({1, w}).stride(1).padding({0, w / 2}).count_include_pad(true));
  };
  const torch::Tensor num = box(inv), den = box(v);
  const torch::Tensor est = torch::where(den > 1e-12, den / num.clamp_min(1e-300), z);
  return est.reshape(depth_m.sizes()).to(depth_m.scalar_type());
}

int64_t structure_window_px(int64_t H, int64_t W, double fraction) {
  if (!(fraction > 0 && fraction <= 1)) throw InputError("depth structure: the fraction must be in (0, 1]");
  const int64_t w = int64_t(std::lround(fraction * double(std::min(H, W))));
  return std::max<int64_t>(1, w % 2 ? w : w - 1);
}

double depth_structure(const torch::Tensor& depth_m, const torch::Tensor& mask, double fraction) {
  const int64_t H = depth_m.size(-2), W = depth_m.size(-1);
  const torch::Tensor z = depth_m.to(torch::kFloat64).reshape({H, W});
  const torch::Tensor v = (mask.reshape({H, W}) > 0.5) & torch::isfinite(z) & (z > 0);
  const double n = v.sum().item<double>();
  if (n < 2) return std::nan("");
  const double med = (1.0 / z.masked_select(v)).median().item<double>();
  const torch::Tensor vf = v.to(torch::kFloat64);
  const torch::Tensor zs = torch::where(v, z, torch::ones_like(z));
  const double constant = std::sqrt(((1.0 / med - zs).square() * vf).sum().item<double>() / n);
  if (!(constant > 0)) return std::nan("");
  const torch::Tensor o = box_oracle_depth_map(zs, vf, structure_window_px(H, W, fraction));
  return std::sqrt(((o - zs).square() * vf).sum().item<double>() / n) / constant;
}

namespace {

// Inverse depth in any unit (0 = unknown) [h, w] -> the reference map at H × W over [near, far].
ReferenceDepthMap to_reference(const std::string& name, const cv::Mat& inv, int64_t H, int64_t W, double near_m,
                               double far_m) {
  cv::Mat valid;
  cv::Mat(inv > 0).convertTo(valid, CV_32F, 1.0 / 255);
  cv::Mat sum, cover;
  cv::resize(inv.mul(valid), sum, cv::Size(int(W), int(H)), 0, 0, cv::INTER_AREA);
  cv::resize(valid, cover, cv::Size(int(W), int(H)), 0, 0, cv::INTER_AREA);
  const torch::Tensor s = torch::from_blob(sum.data, {1, H, W}, torch::kFloat32).clone();
  const torch::Tensor c = torch::from_blob(cover.data, {1, H, W}, torch::kFloat32).clone();
  const torch::Tensor m = c > 0.99f;  // every source pixel of the cell measured
  const torch::Tensor v = s / c.clamp_min(1e-6f);
  const torch::Tensor sorted = std::get<0>(v.masked_select(m).sort());
  if (sorted.numel() < 16) throw InputError(name + ": too few measured pixels for a reference depth map");
  const double lo = sorted[int64_t(0.01 * double(sorted.numel()))].item<double>();
  const double hi = sorted[int64_t(0.99 * double(sorted.numel() - 1))].item<double>();
  if (!(hi > lo)) throw InputError(name + ": a flat reference depth map");
  const torch::Tensor t = (v - lo).clamp(0, hi - lo) / (hi - lo);
  const torch::Tensor inv_m = 1.0 / far_m + t * (1.0 / near_m - 1.0 / far_m);
  return {name, torch::where(m, 1.0 / inv_m, torch::ones_like(inv_m)).to(torch::kFloat32), m.to(torch::kFloat32)};
}

}  // namespace

std::vector<ReferenceDepthMap> reference_depth_maps(int64_t H, int64_t W, double near_m, double far_m) {
  if (H < 8 || W < 8 || !(near_m > 0 && far_m > near_m)) throw InputError("reference depth maps: bad size or range");
  const std::string dir = optics::data_dir() + "/real/";
  std::vector<ReferenceDepthMap> out;
  // A 16-bit depth PNG -> inverse depth [1/m] (0 = unknown), depth_m(v) decoding a sample (<= 0: unknown).
  auto png16 = [&](const std::string& file, auto depth_m) {
    const cv::Mat t = read_image(dir + file, cv::IMREAD_ANYDEPTH, "reference depth map");
    if (t.type() != CV_16U) throw InputError(dir + file + ": expected 16-bit grey");
    cv::Mat inv(t.size(), CV_32F, cv::Scalar(0));
    for (int i = 0; i < t.rows; ++i)
      for (int j = 0; j < t.cols; ++j)
        if (const float z = depth_m(unsigned(t.at<uint16_t>(i, j))); z > 0) inv.at<float>(i, j) = 1.0f / z;
    return inv;
  };
  // TUM: depth [m] = v / 5000. SUN RGB-D: depth [mm] = the 3-bit circular shift of v.
  out.push_back(to_reference("TUM RGB-D (office desk)", png16("rgbd_samples/TUM_depth.png", [](unsigned v) { return float(v) / 5000.0f; }),
                             H, W, near_m, far_m));
  out.push_back(to_reference("SUN RGB-D (office corridor)",
                             png16("rgbd_samples/SUN_depth.png",
                                   [](unsigned v) { return float(((v >> 3) | (v << 13)) & 0xFFFFu) / 1000.0f; }),
                             H, W, near_m, far_m));
  {  // NYU v2 raw Kinect disparity, little-endian after a 17-byte header; 1/depth = (1092.5 - raw) / 351.3
    const std::string path = dir + "rgbd_samples/NYU_depth.pgm";
    std::ifstream f(path, std::ios::binary);
    if (!f) throw InputError(path + ": cannot open (reference depth map)");
    const std::vector<unsigned char> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const int rows = 480, cols = 640;
    if (b.size() != size_t(17 + 2 * rows * cols) || b[0] != 'P' || b[1] != '5')
      throw InputError(path + ": expected the 640 x 480 raw NYU disparity (17-byte P5 header, 16-bit samples)");
    cv::Mat inv(rows, cols, CV_32F, cv::Scalar(0));
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) {
        const size_t k = 17 + 2 * size_t(i * cols + j);
        const unsigned raw = unsigned(b[k]) | (unsigned(b[k + 1]) << 8);
        if (raw < 2047) inv.at<float>(i, j) = (1092.5f - float(raw)) / 351.3f;
      }
    out.push_back(to_reference("NYU Depth v2 (basement)", inv, H, W, near_m, far_m));
  }
  {  // Middlebury Aloe: disparity (inverse depth up to an unknown offset), 0 = unknown
    const cv::Mat t = read_image(dir + "middlebury2006_aloe/aloeGT.png", cv::IMREAD_GRAYSCALE, "reference depth map");
    cv::Mat inv;
    t.convertTo(inv, CV_32F);
    out.push_back(to_reference("Middlebury 2006 Aloe (tabletop)", inv, H, W, near_m, far_m));
  }
  return out;
}

}  // namespace hsd::data
