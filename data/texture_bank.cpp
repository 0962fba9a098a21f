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
    const torch::Tensor Y = (0.2126 * im[0] + 0.7152 * im[1] + 0.0722 * im[2]).reshape(-1);
    const int64_t k = std::max<int64_t>(1, int64_t(0.95 * double(Y.numel())));
    y95_.push_back(std::max(1e-3, std::get<0>(Y.kthvalue(k)).item<double>()));
    grey_.push_back(((im[0] - im[1]).abs().max().item<float>() < 1.0f / 255.0f) &&
                    ((im[0] - im[2]).abs().max().item<float>() < 1.0f / 255.0f));
    names_.push_back(p.filename().string());
  }
}

torch::Tensor sample_mirrored(const torch::Tensor& image, const torch::Tensor& x, const torch::Tensor& y) {
  const int64_t h = image.size(1), w = image.size(2);
  // Mirror into [0, n-1] with period 2(n-1), in float64 before the float32 grid.
  auto mirror = [](const torch::Tensor& c, int64_t n) {
    const double period = 2.0 * double(n - 1);
    const torch::Tensor m = c - torch::floor(c / period) * period;
    return torch::where(m > double(n - 1), period - m, m);
  };
  const torch::Tensor gx = mirror(x, w) * (2.0 / double(w - 1)) - 1.0;
  const torch::Tensor gy = mirror(y, h) * (2.0 / double(h - 1)) - 1.0;
  const torch::Tensor grid = torch::stack({gx, gy}, -1).unsqueeze(0).to(torch::kFloat32);  // [1, H, W, 2]
  const torch::Tensor out = torch::grid_sampler(image.unsqueeze(0).to(torch::kFloat32), grid, /*bilinear*/ 0, /*border*/ 1,
                                                /*align_corners*/ true);
  return out.squeeze(0).to(torch::kFloat64);
}

}  // namespace hsd::data
