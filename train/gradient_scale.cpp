#include "train/gradient_scale.h"

#include <cmath>

#include "common/error.h"

namespace hsd::train {
namespace {

struct GradientScale : torch::autograd::Function<GradientScale> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x, double k) {
    ctx->saved_data["k"] = k;
    return x.view_as(x);  // the same values; a new node for the backward
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grad) {
    const double k = ctx->saved_data["k"].toDouble();
    return {grad[0] * k, torch::Tensor()};
  }
};

}  // namespace

torch::Tensor scale_gradient(const torch::Tensor& x, double k) {
  if (!std::isfinite(k)) throw NumericalError("scale_gradient: the scale is not finite");
  if (k == 1.0 || !x.requires_grad()) return x;
  return GradientScale::apply(x, k);
}

}  // namespace hsd::train
