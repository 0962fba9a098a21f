#include "common/error.h"

#include <torch/torch.h>

namespace hsd {

void input_error(const std::string& where, const std::string& what) {
  throw InputError(where + ": " + what);
}

void check_finite(const at::Tensor& t, const std::string& where) {
  if (!t.defined() || !(t.is_floating_point() || t.is_complex())) return;
  const at::Tensor v = t.detach();
  if (!torch::isfinite(v).all().item<bool>()) {
    const int64_t bad = (~torch::isfinite(v)).sum().item<int64_t>();
    throw NumericalError("non-finite values (NaN or Inf) in " + where + ": " +
                         std::to_string(bad) + " of " + std::to_string(v.numel()) +
                         " elements");
  }
}

}  // namespace hsd
