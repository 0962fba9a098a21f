// Whether a tensor is still the one seen before, with the same values,
// without comparing its values: the key of the filters HsdNet keeps between
// calls (unet.h). A snapshot holds the tensor (so its memory cannot be handed
// to another tensor while the snapshot lives) and its version counter, which
// every in-place write through torch bumps, also through views and detached
// aliases. A tensor matches when it has the same data pointer, sizes,
// strides, dtype and device, and neither it nor the held tensor has been
// written since. (Writes that bypass the version counter, through
// Tensor::data() or raw pointers, are not seen: nothing in hsd writes PSFs or
// priors so.)
#pragma once
#include <cstdint>

#include <torch/types.h>

namespace hsd::model {

class TensorSnapshot {
 public:
  TensorSnapshot() = default;
  explicit TensorSnapshot(const torch::Tensor& t) : held_(t), version_(t.defined() ? int64_t(t._version()) : -1) {}
  bool matches(const torch::Tensor& t) const {
    return t.defined() && held_.defined() && t.data_ptr() == held_.data_ptr() && t.sizes() == held_.sizes() &&
           t.strides() == held_.strides() && t.dtype() == held_.dtype() && t.device() == held_.device() &&
           int64_t(t._version()) == version_ && int64_t(held_._version()) == version_;
  }
  bool empty() const { return !held_.defined(); }

 private:
  torch::Tensor held_;
  int64_t version_ = -1;
};

}  // namespace hsd::model
