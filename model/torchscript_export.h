// The network as a self-contained TorchScript module (docs/formats.md, "Exported
// reconstructor"): forward(x [B, 3, H, W] linear sensor RGB) -> (hs [B, L, H, W],
// depth [B, 1, H, W] metres). C++ cannot script a torch::nn::Module, so the
// exporter writes HsdNet's forward pass as TorchScript source (generated for
// its levels and normalisation, in eval mode) on a torch::jit::Module that
// holds copies of the weights, the spectral-upsampling weights and the depth
// mapping; inputs of any size are padded as HsdNet pads them. The forward
// pass therefore exists twice, HsdNetImpl::forward (model/unet.cpp) and the
// source written here (with the Wiener pre-inversion and fast FFT sizes): a
// change to one must be made in the other; tests/model/test_export.cpp checks that
// both give the same output for every normalisation and residual choice.
#pragma once
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <torch/script.h>

#include "model/unet.h"

namespace hsd::model {

struct ExportMetadata {
  std::vector<double> wavelengths_m;
  std::map<std::string, std::string> strings;  // e.g. camera, doe, config_sha, hsd_version
  std::map<std::string, double> numbers;       // e.g. baseline_inv_depth_per_m (train/baselines.h)
};

// A module loadable by torch::jit::load and Python's torch.jit.load.
torch::jit::Module export_torchscript(HsdNet& net, const ExportMetadata& meta);

// Runs the network of an exported reconstructor in `dtype` (float32 or
// bfloat16) with channels-last weights; inputs and outputs stay float32 and the
// spectral-upsampling residual stays float32. bfloat16 is several times faster
// on CPUs with native bfloat16 (AVX512-BF16, AMX) at ~0.3% mean error
// (hsd_bench reconstruct measures both).
void set_reconstructor_precision(torch::jit::Module& m, c10::ScalarType dtype);

// Loads an exported reconstructor (eval mode); InputError naming the file when
// it is missing, not TorchScript, or lacks forward / wavelengths_m / depth_range_m.
torch::jit::Module load_reconstructor(const std::string& path);

// forward of a reconstructor: x [B, 3, H, W] -> (hs [B, L, H, W], depth [B, 1, H, W]).
std::pair<torch::Tensor, torch::Tensor> run_reconstructor(torch::jit::Module& m, const torch::Tensor& x);

}  // namespace hsd::model
