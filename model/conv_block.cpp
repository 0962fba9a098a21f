#include "model/conv_block.h"

#include <algorithm>

#include "model/sync_batch_norm.h"

namespace hsd::model {

torch::nn::Sequential conv_block(int64_t in, int64_t out, NormKind norm) {
  torch::nn::Sequential s;
  for (int k = 0; k < 2; ++k) {
    s->push_back(torch::nn::Conv2d(torch::nn::Conv2dOptions(k == 0 ? in : out, out, 3).padding(1).bias(norm == NormKind::none)));
    if (norm == NormKind::batch) s->push_back(SyncBatchNorm2d(out));
    else if (norm == NormKind::group) s->push_back(torch::nn::GroupNorm(std::min<int64_t>(8, out), out));
    s->push_back(torch::nn::ReLU(true));
  }
  return s;
}

}  // namespace hsd::model
