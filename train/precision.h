// The network's arithmetic in training steps (train.precision;
// docs/training.md): float32, or bfloat16 convolutions under float32 master weights
// (model/unet.h, "Mixed precision"). "auto" takes bfloat16 on a CPU with
// native bfloat16 dot products (AVX512-BF16 or AMX-BF16), float32 elsewhere.
// The library default is "float32"; configs/paper.json takes "auto": on the
// quick config (same seed) bfloat16 ended within 1% of float32's validation
// loss (the criterion is 2%; an earlier quick config ended 14.5% above), and
// the paper step is 1.3-1.45x faster (docs/training.md).
#pragma once
#include <string>

#include <torch/types.h>

#include "common/choices.h"

namespace hsd::train {

// True on a Linux CPU whose flags (/proc/cpuinfo) include avx512_bf16 or amx_bf16.
bool cpu_has_native_bf16();

struct TrainingPrecision {
  torch::ScalarType dtype = torch::kFloat32;  // kFloat32 | kBFloat16
  std::string why;                            // one line for the log, e.g. "bfloat16 (auto: the CPU has AVX512-BF16)"
};

// precision: train.precision. "auto" is bfloat16 on a CPU device with native bfloat16, float32 otherwise
// (CUDA included: its mixed precision is not measured here).
TrainingPrecision training_precision(TrainPrecision precision, torch::Device device);

}  // namespace hsd::train
