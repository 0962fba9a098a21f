// Natural photographs as surface textures for the realistic generator: every
// image file (.jpg, .jpeg, .png, .tif, .tiff, .bmp) of a folder, sorted by name,
// decoded from sRGB to linear RGB in [0, 1], the longest side reduced to at most
// `max_side_px` (area averaging). The default folder, data/textures/, ships with
// hsd (sources and licences in its README); data.generator.texture_dir points
// the generator at any other folder (a user's photos, a texture dataset).
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

// image [C, h, w] (any float) at pixel coordinates x, y [H, W] (x right, y down,
// pixel centres at integers): bilinear, mirrored beyond the edges (period
// 2(n−1), no seams at any scale). Returns float64 [C, H, W].
torch::Tensor sample_mirrored(const torch::Tensor& image, const torch::Tensor& x, const torch::Tensor& y);

class TextureBank {
 public:
  // InputError naming the folder when it has no readable image, or naming a
  // file that cannot be decoded or is smaller than 16 x 16 pixels.
  explicit TextureBank(const std::string& dir, int64_t max_side_px = 1024);
  static std::string default_dir();  // optics::data_dir() + "/textures"
  int64_t size() const { return int64_t(images_.size()); }
  const std::string& name(int64_t i) const { return names_[size_t(i)]; }
  const torch::Tensor& image(int64_t i) const { return images_[size_t(i)]; }  // float32 [3, h, w], linear RGB
  // 95th percentile of image i's luminance (Rec. 709 weights of linear RGB), > 0.
  double luminance_p95(int64_t i) const { return y95_[size_t(i)]; }
  // True when image i has no colour (every pixel's channels within 1/255).
  bool is_grey(int64_t i) const { return grey_[size_t(i)]; }

  // Texture i at texture-pixel coordinates x, y [H, W] (sample_mirrored). Returns float64 [3, H, W].
  torch::Tensor sample(int64_t i, const torch::Tensor& x, const torch::Tensor& y) const {
    return sample_mirrored(images_[size_t(i)], x, y);
  }

 private:
  std::vector<std::string> names_;
  std::vector<torch::Tensor> images_;
  std::vector<double> y95_;
  std::vector<bool> grey_;
};

}  // namespace hsd::data
