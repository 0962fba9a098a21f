#include "data/image_io.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"

namespace hsd::data {

namespace {

uint32_t big_endian(const unsigned char* p) {
  return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | uint32_t(p[3]);
}

// PNG (ISO/IEC 15948): 8-byte signature, then the IHDR chunk (length 13,
// width and height big-endian), and the IEND chunk as the file's last 12 bytes.
void check_png_structure(const std::string& path, std::ifstream& f, const std::array<unsigned char, 8>& sig) {
  static const unsigned char kSig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (std::memcmp(sig.data(), kSig, 8) != 0) input_error(path, "not a PNG file (bad signature)");
  unsigned char ihdr[16];
  if (!f.read(reinterpret_cast<char*>(ihdr), 16) || std::memcmp(ihdr + 4, "IHDR", 4) != 0)
    input_error(path, "truncated or damaged PNG (no IHDR header)");
  const uint64_t w = big_endian(ihdr + 8), h = big_endian(ihdr + 12);
  if (w == 0 || h == 0) input_error(path, "PNG header says " + std::to_string(w) + "x" + std::to_string(h) + " pixels");
  if (w * h > (uint64_t(1) << 28))
    input_error(path, "PNG header says " + std::to_string(w) + "x" + std::to_string(h) + " pixels (over 2^28; refused)");
  f.seekg(-12, std::ios::end);
  unsigned char tail[12];
  if (!f.read(reinterpret_cast<char*>(tail), 12) || std::memcmp(tail + 4, "IEND", 4) != 0)
    input_error(path, "truncated PNG (the file ends before its IEND chunk)");
}

}  // namespace

cv::Mat read_image(const std::string& path, int flags, const std::string& what) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) input_error(path, "no such file (" + what + ")");
  if (!std::filesystem::is_regular_file(path, ec)) input_error(path, "not a regular file (" + what + ")");
  std::ifstream f(path, std::ios::binary);
  if (!f) input_error(path, std::string("cannot open (") + std::strerror(errno) + ")");
  std::array<unsigned char, 8> sig{};
  if (!f.read(reinterpret_cast<char*>(sig.data()), 8)) input_error(path, "not an image (under 8 bytes)");
  if (sig[0] == 0x89 && sig[1] == 'P') check_png_structure(path, f, sig);
  cv::Mat m;
  try {
    m = cv::imread(path, flags);
  } catch (const cv::Exception& e) {
    input_error(path, "cannot be decoded as an image (OpenCV: " + std::string(e.err) + ")");
  }
  if (m.empty()) input_error(path, "cannot be decoded as an image (" + what + ")");
  return m;
}

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
