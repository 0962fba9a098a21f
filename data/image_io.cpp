#include "data/image_io.h"

#include <opencv2/imgcodecs.hpp>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"

namespace hsd::data {

torch::Tensor srgb_to_linear(const torch::Tensor& v) {
  return torch::where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055).pow(2.4));
}

void write_srgb_png(const std::string& path, const torch::Tensor& rgb, double white) {
  if (rgb.dim() != 3 || rgb.size(0) != 3) input_error(path, "preview needs a [3, H, W] image");
  torch::Tensor v = (rgb.detach().to(torch::kFloat64).cpu() / (white > 0 ? white : 1.0)).clamp(0.0, 1.0);
  v = torch::where(v <= 0.0031308, 12.92 * v, 1.055 * v.pow(1.0 / 2.4) - 0.055);
  // [3, H, W] RGB -> [H, W, 3] BGR bytes for OpenCV
  const torch::Tensor bgr = (v.flip(0).permute({1, 2, 0}) * 255.0 + 0.5).clamp(0, 255).to(torch::kUInt8).contiguous();
  const cv::Mat img(int(bgr.size(0)), int(bgr.size(1)), CV_8UC3, bgr.data_ptr<uint8_t>());
  std::vector<uchar> buf;
  if (!cv::imencode(".png", img, buf)) input_error(path, "PNG encoding failed");
  write_binary_file(path, std::vector<char>(buf.begin(), buf.end()));
}

}  // namespace hsd::data
