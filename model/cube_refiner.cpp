#include "model/cube_refiner.h"

#include <string>

#include "model/conv_block.h"

namespace hsd::model {

namespace F = torch::nn::functional;

CubeRefinerImpl::CubeRefinerImpl(const CubeRefinerOptions& options) : opt_(options) {
  TORCH_CHECK(opt_.levels >= 1 && opt_.levels <= 8, "CubeRefiner: levels must be in [1, 8]");
  TORCH_CHECK(opt_.base_width >= 1 && opt_.in_channels >= 1 && opt_.bands >= 1,
              "CubeRefiner: base_width, in_channels and bands must be >= 1");
  std::vector<int64_t> width;
  for (int64_t l = 0; l <= opt_.levels; ++l) width.push_back(opt_.base_width << l);
  for (int64_t l = 0; l < opt_.levels; ++l)
    down_.push_back(register_module("down" + std::to_string(l),
                                    conv_block(l == 0 ? opt_.in_channels + opt_.bands : width[size_t(l - 1)], width[size_t(l)], opt_.norm)));
  bottom_ = register_module("bottom", conv_block(width[size_t(opt_.levels - 1)], width[size_t(opt_.levels)], opt_.norm));
  for (int64_t l = opt_.levels - 1; l >= 0; --l) {
    const std::string s = std::to_string(l);
    const int64_t w = width[size_t(l)], below = width[size_t(l + 1)];
    up_.push_back(register_module("up" + s, torch::nn::Conv2d(torch::nn::Conv2dOptions(below, w, 3).padding(1))));
    dec_.push_back(register_module("dec" + s, conv_block(2 * w, w, opt_.norm)));
  }
  head_ = register_module("head", torch::nn::Conv2d(torch::nn::Conv2dOptions(width[0], opt_.bands, 1)));
}

torch::Tensor CubeRefinerImpl::forward(const torch::Tensor& image, const torch::Tensor& cube) {
  TORCH_CHECK(image.dim() == 4 && image.size(1) == opt_.in_channels, "CubeRefiner: image must be [B, ",
              opt_.in_channels, ", H, W], got ", image.sizes());
  TORCH_CHECK(cube.dim() == 4 && cube.size(0) == image.size(0) && cube.size(1) == opt_.bands &&
                  cube.size(2) == image.size(2) && cube.size(3) == image.size(3),
              "CubeRefiner: cube must be [B, ", opt_.bands, ", H, W] like the image, got ", cube.sizes());
  const int64_t H = image.size(2), W = image.size(3), m = int64_t(1) << opt_.levels;
  const int64_t ph = (m - H % m) % m, pw = (m - W % m) % m;
  torch::Tensor x = torch::cat({image.to(torch::kFloat32), cube.to(torch::kFloat32)}, 1);
  if (ph || pw) {  // reflect needs pad < size; replicate always works
    F::PadFuncOptions o({0, pw, 0, ph});
    if (ph < H && pw < W) o.mode(torch::kReflect);
    else o.mode(torch::kReplicate);
    x = F::pad(x, o);
  }
  std::vector<torch::Tensor> skips;
  for (auto& d : down_) {
    x = d->forward(x);
    skips.push_back(x);
    x = F::max_pool2d(x, F::MaxPool2dFuncOptions(2));
  }
  torch::Tensor y = bottom_->forward(x);
  for (size_t k = 0; k < up_.size(); ++k) {
    const torch::Tensor& skip = skips[skips.size() - 1 - k];
    y = F::interpolate(y, F::InterpolateFuncOptions()
                              .size(std::vector<int64_t>{skip.size(2), skip.size(3)})
                              .mode(torch::kBilinear)
                              .align_corners(false));
    y = torch::relu(up_[k]->forward(y));
    y = dec_[k]->forward(torch::cat({y, skip}, 1));
  }
  torch::Tensor r = head_->forward(y);
  if (ph || pw) r = r.narrow(2, 0, H).narrow(3, 0, W);
  return r.contiguous();
}

void CubeRefinerImpl::start_at_zero() {
  torch::NoGradGuard no_grad;
  head_->weight.zero_();
  head_->bias.zero_();
}

}  // namespace hsd::model
