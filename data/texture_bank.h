// Natural photographs as surface textures for the realistic generator: every
// image file (.jpg, .jpeg, .png, .tif, .tiff, .bmp) of a folder, sorted by name,
// decoded from sRGB to linear RGB in [0, 1], the longest side reduced to at most
// `max_side_px` (area averaging), with a pyramid of area-averaged halvings for
// reads averaged over a scene pixel's footprint. The default folder, data/textures/, ships with
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

  // Texture i at texture-pixel coordinates x, y [H, W] (sample_mirrored), point
  // sampled: a scene pixel spanning several texture pixels aliases. Returns float64 [3, H, W].
  torch::Tensor sample(int64_t i, const torch::Tensor& x, const torch::Tensor& y) const {
    return sample_mirrored(images_[size_t(i)], x, y);
  }
  // The same, averaged over each scene pixel's footprint, as a sensor pixel
  // integrates the radiance over its area: `footprint` [H, W] is the texture
  // pixels one scene pixel spans (>= 0; <= 1 gives sample() exactly). Trilinear
  // in a pyramid of area-averaged halvings (level k = 2^k texture pixels per
  // texel; level log2(footprint), interpolated between the two nearest levels;
  // the coarsest level beyond its reach). Returns float64 [3, H, W].
  torch::Tensor sample_area(int64_t i, const torch::Tensor& x, const torch::Tensor& y, const torch::Tensor& footprint) const;
  int64_t levels(int64_t i) const { return int64_t(pyramids_[size_t(i)].size()); }  // level 0 = image(i)

 private:
  std::vector<std::string> names_;
  std::vector<torch::Tensor> images_;
  std::vector<std::vector<torch::Tensor>> pyramids_;  // per image: level 0 (the image), 1, 2, ... halvings, down to 8 px
  std::vector<double> y95_;
  std::vector<bool> grey_;
};

}  // namespace hsd::data
