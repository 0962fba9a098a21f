#include "data/image_io.h"

#include <algorithm>

#include <opencv2/imgcodecs.hpp>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"

namespace hsd::data {

torch::Tensor srgb_to_linear(const torch::Tensor& v) {
  // In bands of rows (dim -2) so a large frame makes no full-size temporaries.
  torch::Tensor out = torch::empty_like(v);
  const int64_t rows = v.size(-2);
  for (int64_t r = 0; r < rows; r += 256) {
    const int64_t n = std::min<int64_t>(256, rows - r);
    const torch::Tensor c = v.narrow(-2, r, n);
    out.narrow(-2, r, n).copy_(torch::where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055).pow(2.4)));
  }
  return out;
}

void write_srgb_png(const std::string& path, const torch::Tensor& rgb, double white) {
  if (rgb.dim() != 3 || rgb.size(0) != 3) input_error(path, "preview needs a [3, H, W] image");
  const int64_t H = rgb.size(1), W = rgb.size(2);
  // [3, H, W] RGB -> [H, W, 3] BGR bytes for OpenCV, encoded in bands of rows
  // (a 22-megapixel frame would otherwise make ~3 GB of float64 temporaries).
  torch::Tensor bgr = torch::empty({H, W, 3}, torch::kUInt8);
  const torch::Tensor src = rgb.detach().cpu();
  for (int64_t r = 0; r < H; r += 256) {
    const int64_t n = std::min<int64_t>(256, H - r);
    torch::Tensor v = (src.narrow(1, r, n).to(torch::kFloat32) / float(white > 0 ? white : 1.0)).clamp(0.0, 1.0);
    v = torch::where(v <= 0.0031308, 12.92 * v, 1.055 * v.pow(1.0 / 2.4) - 0.055);
    bgr.narrow(0, r, n).copy_((v.flip(0).permute({1, 2, 0}) * 255.0 + 0.5).clamp(0, 255).to(torch::kUInt8));
  }
  const cv::Mat img(int(H), int(W), CV_8UC3, bgr.data_ptr<uint8_t>());
  std::vector<uchar> buf;
  if (!cv::imencode(".png", img, buf)) input_error(path, "PNG encoding failed");
  write_binary_file(path, std::vector<char>(buf.begin(), buf.end()));
}

}  // namespace hsd::data
