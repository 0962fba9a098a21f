#include "common/sample_stats.h"

#include <cmath>

namespace hsd {

SampleStats sample_stats(const std::vector<double>& v) {
  SampleStats s;
  s.n = v.size();
  if (v.empty()) return s;
  for (double x : v) s.mean += x;
  s.mean /= double(v.size());
  double q = 0;
  for (double x : v) q += (x - s.mean) * (x - s.mean);
  s.sd = v.size() > 1 ? std::sqrt(q / double(v.size() - 1)) : 0.0;
  return s;
}

}  // namespace hsd
