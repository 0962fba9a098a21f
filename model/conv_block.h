// The U-Nets' block (Baek et al. 2021, "Network Architecture"; HsdNet and the
// cube refiner): conv 3×3 (padding 1) -> norm -> ReLU, twice. The convolutions
// carry a bias only without a norm (a norm's shift replaces it); batch norm is
// SyncBatchNorm2d (synchronised once its replica group is set), group norm
// uses min(8, channels) groups.
#pragma once
#include <torch/torch.h>

#include "common/choices.h"

namespace hsd::model {

// in -> out channels, spatial size kept.
torch::nn::Sequential conv_block(int64_t in, int64_t out, NormKind norm);

}  // namespace hsd::model
