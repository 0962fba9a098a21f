// A second reconstruction stage for the cube (not in Baek et al. 2021): a
// U-Net of its own, with one decoder, that reads the sensor image beside the
// first stage's cube and adds a residual to that cube,
//     x₂ = x₁ + R([y, x₁]),
// the second half of an unrolled reconstructor (a network, a data step, a
// network: the data step is HsdNet's project_residual, which the owner
// applies to R's output too). The first stage's depth is left as it is: the
// refiner has no depth output, so its features serve the cube alone (seeing
// the cube in the first stage, model.base_as_input, cost depth:
// docs/learning.md). Its head starts at zero (start_at_zero), so a network
// started at the baselines still scores exactly them. HsdNet reports x₁
// beside x₂ (NetOutput::first_stage_hs) for train.first_stage_cube_weight,
// the deep supervision of the first stage. Its blocks are
// HsdNet's (conv_block.h); inputs whose sides are not multiples of
// 2^levels are padded and the output cropped back. Float32 always (the
// trainer's bfloat16 covers the first stage only).
#pragma once
#include <vector>

#include <torch/torch.h>

#include "common/choices.h"

namespace hsd::model {

struct CubeRefinerOptions {
  int64_t in_channels = 3;  // C, the image's
  int64_t bands = 25;       // L, the cube's
  int64_t base_width = 16;  // channels of the first level; doubled per level
  int64_t levels = 3;       // poolings, in [1, 8]
  NormKind norm = NormKind::group;
};

class CubeRefinerImpl : public torch::nn::Module {
 public:
  explicit CubeRefinerImpl(const CubeRefinerOptions& options);
  // image [B, C, H, W], cube [B, L, H, W] (the first stage's, float32) ->
  // the residual R [B, L, H, W] float32 (the owner adds it to the cube).
  torch::Tensor forward(const torch::Tensor& image, const torch::Tensor& cube);
  // Zeroes the head: R = 0 for every input until the first update.
  void start_at_zero();
  const CubeRefinerOptions& options() const { return opt_; }

 private:
  CubeRefinerOptions opt_;
  std::vector<torch::nn::Sequential> down_, dec_;
  torch::nn::Sequential bottom_{nullptr};
  std::vector<torch::nn::Conv2d> up_;
  torch::nn::Conv2d head_{nullptr};
};
TORCH_MODULE(CubeRefiner);

}  // namespace hsd::model
