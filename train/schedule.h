// Learning-rate schedule shared by both parameter groups: linear warm-up over
// warmup_steps, then constant ("none") or a cosine decay to min_ratio at the
// last step. A pure function of the step, so a resumed run needs no state.
#pragma once
#include <cstdint>
#include <string>

#include "common/choices.h"

namespace hsd::train {

// Factor in (0, 1] multiplying the base rate at `step` (0-based) of `total` steps.
double lr_factor(int64_t step, int64_t total, int64_t warmup_steps, LrDecay decay, double min_ratio);

}  // namespace hsd::train
