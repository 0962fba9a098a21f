// Mean and sample standard deviation of a list of numbers (seeds of an
// ablation, random draws of a tolerance sweep), reported as mean ± SD.
#pragma once
#include <cstddef>
#include <vector>

namespace hsd {

struct SampleStats {
  double mean = 0;  // arithmetic mean (0 for an empty list)
  double sd = 0;    // sample standard deviation, divisor n - 1 (0 for n < 2)
  size_t n = 0;     // how many values
};

SampleStats sample_stats(const std::vector<double>& v);

}  // namespace hsd
