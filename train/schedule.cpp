#include "train/schedule.h"

#include <algorithm>
#include <cmath>

namespace hsd::train {

double lr_factor(int64_t step, int64_t total, int64_t warmup_steps, LrDecay decay, double min_ratio) {
  const double warm = warmup_steps > 0 ? std::min(1.0, double(step + 1) / double(warmup_steps)) : 1.0;
  if (decay != LrDecay::cosine || total <= warmup_steps + 1) return warm;
  const double t = std::clamp(double(step - warmup_steps) / double(total - 1 - warmup_steps), 0.0, 1.0);
  return warm * (min_ratio + (1.0 - min_ratio) * 0.5 * (1.0 + std::cos(M_PI * t)));
}

}  // namespace hsd::train
