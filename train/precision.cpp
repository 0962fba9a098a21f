#include "train/precision.h"

#include <fstream>
#include <sstream>

namespace hsd::train {

bool cpu_has_native_bf16() {
  static const bool has = [] {
    std::ifstream in("/proc/cpuinfo");
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("flags", 0) != 0) continue;
      std::istringstream words(line);
      for (std::string w; words >> w;)
        if (w == "avx512_bf16" || w == "amx_bf16") return true;
      return false;  // the first processor's flags speak for all
    }
    return false;
  }();
  return has;
}

TrainingPrecision training_precision(TrainPrecision precision, torch::Device device) {
  if (precision == TrainPrecision::float32) return {torch::kFloat32, "float32 (train.precision)"};
  if (precision == TrainPrecision::bfloat16) {
    if (!device.is_cpu()) return {torch::kBFloat16, "bfloat16 (train.precision)"};
    return {torch::kBFloat16, cpu_has_native_bf16() ? "bfloat16 (train.precision; the CPU has native bfloat16)"
                                                    : "bfloat16 (train.precision; the CPU has no native bfloat16: emulated, likely slower than float32)"};
  }
  if (!device.is_cpu()) return {torch::kFloat32, "float32 (auto: bfloat16 training is measured on CPUs only)"};
  if (cpu_has_native_bf16()) return {torch::kBFloat16, "bfloat16 (auto: the CPU has native bfloat16)"};
  return {torch::kFloat32, "float32 (auto: the CPU has no native bfloat16)"};
}

}  // namespace hsd::train
