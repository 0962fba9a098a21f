#include "common/error.h"

#include <cmath>
#include <vector>

#include <torch/torch.h>

namespace hsd {

void input_error(const std::string& where, const std::string& what) {
  throw InputError(where + ": " + what);
}

std::string first_nonfinite(const at::Tensor& t) {
  if (!t.defined() || !(t.is_floating_point() || t.is_complex())) return "";
  if (t.is_complex()) return first_nonfinite(torch::view_as_real(t.detach().contiguous()));
  const at::Tensor bad = ~torch::isfinite(t.detach());
  if (!bad.any().item<bool>()) return "";
  const int64_t count = bad.sum().item<int64_t>();
  int64_t flat = bad.reshape(-1).nonzero()[0][0].item<int64_t>();
  const double v = t.detach().reshape(-1)[flat].item<double>();
  std::vector<int64_t> idx(size_t(t.dim()));
  for (int64_t d = t.dim() - 1; d >= 0; --d) idx[size_t(d)] = flat % t.size(d), flat /= t.size(d);
  std::string s = std::isnan(v) ? "NaN" : (v > 0 ? "+Inf" : "-Inf");
  s += " at [";
  for (size_t d = 0; d < idx.size(); ++d) s += (d ? ", " : "") + std::to_string(idx[d]);
  return s + "] (" + std::to_string(count) + " of " + std::to_string(t.numel()) + " values)";
}

void check_finite(const at::Tensor& t, const std::string& where) {
  if (!t.defined() || !(t.is_floating_point() || t.is_complex())) return;
  if (torch::isfinite(t.detach()).all().item<bool>()) return;
  throw NumericalError("non-finite values in " + where + ": " + first_nonfinite(t));
}

void check_finite_input(const at::Tensor& t, const std::string& file, const std::string& what) {
  const std::string bad = first_nonfinite(t);
  if (!bad.empty()) input_error(file, what + " holds " + bad);
}

}  // namespace hsd
