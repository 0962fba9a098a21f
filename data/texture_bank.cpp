#include "data/texture_bank.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/torch.h>

#include "common/error.h"
#include "data/image_io.h"
#include "optics/spectrum.h"

namespace hsd::data {

namespace {

// Area-averaged halvings of a float32 [3, h, w] image until its shorter side
// would drop below 8 px; level 0 is the image itself.
std::vector<torch::Tensor> area_pyramid(const torch::Tensor& image) {
  std::vector<torch::Tensor> levels{image};
  while (std::min(levels.back().size(1), levels.back().size(2)) >= 16) {
    const torch::Tensor prev = levels.back();  // a handle: push_back below may move the vector
    const int64_t h = prev.size(1), w = prev.size(2);
    const torch::Tensor hwc_t = prev.permute({1, 2, 0}).contiguous();  // alive while cv reads it
    const cv::Mat hwc(int(h), int(w), CV_32FC3, hwc_t.data_ptr<float>());
    cv::Mat half;
    cv::resize(hwc, half, cv::Size(int((w + 1) / 2), int((h + 1) / 2)), 0, 0, cv::INTER_AREA);
    levels.push_back(torch::from_blob(half.data, {half.rows, half.cols, 3}, torch::kFloat32).permute({2, 0, 1}).contiguous());
  }
  return levels;
}

}  // namespace

std::string TextureBank::default_dir() { return optics::data_dir() + "/textures"; }

TextureBank::TextureBank(const std::string& dir, int64_t max_side_px) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) input_error("config key data.generator.texture_dir", "\"" + dir + "\" is not a folder");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    std::string ext = e.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (e.is_regular_file() && (ext == ".jpg" || ext == ".jpeg" || ext == ".png" || ext == ".tif" || ext == ".tiff" || ext == ".bmp"))
      files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) input_error("config key data.generator.texture_dir", "\"" + dir + "\" holds no image (.jpg, .png, .tif, .bmp)");
  for (const auto& p : files) {
    cv::Mat img = read_image(p.string(), cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH, "data.generator.texture_dir");
    if (img.rows < 16 || img.cols < 16) input_error(p.string(), "is smaller than 16 x 16 pixels");
    const double scale = double(max_side_px) / double(std::max(img.rows, img.cols));
    if (scale < 1.0) cv::resize(img, img, cv::Size(), scale, scale, cv::INTER_AREA);
    cv::Mat f;
    img.convertTo(f, CV_32F, img.depth() == CV_16U ? 1.0 / 65535.0 : 1.0 / 255.0);
    cv::cvtColor(f, f, cv::COLOR_BGR2RGB);
    const torch::Tensor hwc = torch::from_blob(f.data, {f.rows, f.cols, 3}, torch::kFloat32).clone();
    images_.push_back(srgb_to_linear(hwc.permute({2, 0, 1}).contiguous().clamp(0, 1)).to(torch::kFloat32).contiguous());
    const torch::Tensor& im = images_.back();
    pyramids_.push_back(area_pyramid(im));
    const torch::Tensor Y = (0.2126 * im[0] + 0.7152 * im[1] + 0.0722 * im[2]).reshape(-1);
    const int64_t k = std::max<int64_t>(1, int64_t(0.95 * double(Y.numel())));
    y95_.push_back(std::max(1e-3, std::get<0>(Y.kthvalue(k)).item<double>()));
    grey_.push_back(((im[0] - im[1]).abs().max().item<float>() < 1.0f / 255.0f) &&
                    ((im[0] - im[2]).abs().max().item<float>() < 1.0f / 255.0f));
    names_.push_back(p.filename().string());
  }
}

namespace {

// Mirror pixel coordinates into [0, n-1] with period 2(n-1), in float64.
torch::Tensor mirror(const torch::Tensor& c, int64_t n) {
  const double period = 2.0 * double(n - 1);
  const torch::Tensor cd = c.to(torch::kFloat64);
  const torch::Tensor m = cd - torch::floor(cd / period) * period;
  return torch::where(m > double(n - 1), period - m, m);
}

}  // namespace

torch::Tensor sample_mirrored(const torch::Tensor& image, const torch::Tensor& x, const torch::Tensor& y) {
  const int64_t h = image.size(1), w = image.size(2);
  // Mirrored in float64 before the float32 grid.
  const torch::Tensor gx = mirror(x, w) * (2.0 / double(w - 1)) - 1.0;
  const torch::Tensor gy = mirror(y, h) * (2.0 / double(h - 1)) - 1.0;
  const torch::Tensor grid = torch::stack({gx, gy}, -1).unsqueeze(0).to(torch::kFloat32);  // [1, H, W, 2]
  const torch::Tensor out = torch::grid_sampler(image.unsqueeze(0).to(torch::kFloat32), grid, /*bilinear*/ 0, /*border*/ 1,
                                                /*align_corners*/ true);
  return out.squeeze(0).to(torch::kFloat64);
}

torch::Tensor TextureBank::sample_area(int64_t i, const torch::Tensor& x, const torch::Tensor& y,
                                       const torch::Tensor& footprint) const {
  const auto& pyr = pyramids_[size_t(i)];
  const int64_t top = int64_t(pyr.size()) - 1;
  const int64_t h0 = pyr[0].size(1), w0 = pyr[0].size(2);
  // The pyramid level in [0, top]: log2 of the footprint, 0 where it is at most one texture pixel.
  // A footprint that is not finite (no generator makes one) reads level 0 rather than nothing.
  const torch::Tensor fp = torch::nan_to_num(footprint.to(torch::kFloat64), 1.0, 1.0, 1.0);
  const torch::Tensor level = torch::log2(fp.clamp_min(1.0)).clamp_max(double(top));
  const torch::Tensor lo = level.floor().to(torch::kLong).clamp_max(std::max<int64_t>(top - 1, 0));
  const torch::Tensor frac = (level - lo.to(torch::kFloat64)).clamp(0.0, 1.0);
  torch::Tensor out = torch::zeros({3, x.size(0), x.size(1)}, torch::kFloat64);
  // Level k's texel j covers level 0's [j, j + 1) · (n0 / nk) - 1/2: centre (j + 1/2) n0 / nk - 1/2.
  auto at_level = [&](int64_t k, const torch::Tensor& xs, const torch::Tensor& ys) {
    if (k == 0) return sample_mirrored(pyr[0], xs, ys);  // exactly sample() (already mirrored)
    const double sx = double(pyr[size_t(k)].size(2)) / double(w0), sy = double(pyr[size_t(k)].size(1)) / double(h0);
    return sample_mirrored(pyr[size_t(k)], (xs + 0.5) * sx - 0.5, (ys + 0.5) * sy - 0.5);  // [3, 1, n]
  };
  // Mirrored at level 0 first, so every level samples the same place of the photo.
  const torch::Tensor fx = mirror(x.reshape(-1), w0), fy = mirror(y.reshape(-1), h0), flo = lo.reshape(-1), ffr = frac.reshape(-1);
  torch::Tensor flat = out.view({3, -1});
  for (int64_t k = 0; k <= std::max<int64_t>(top - 1, 0); ++k) {
    const torch::Tensor idx = (flo == k).nonzero().squeeze(1);
    if (idx.numel() == 0) continue;
    const torch::Tensor xs = fx.index_select(0, idx).view({1, -1}), ys = fy.index_select(0, idx).view({1, -1});
    const torch::Tensor f = ffr.index_select(0, idx);
    torch::Tensor v = at_level(k, xs, ys).view({3, -1});
    if (k + 1 <= top && f.gt(0).any().item<bool>()) v = v * (1.0 - f) + at_level(k + 1, xs, ys).view({3, -1}) * f;
    flat.index_copy_(1, idx, v);
  }
  return out;
}

}  // namespace hsd::data
