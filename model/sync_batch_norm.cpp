#include "model/sync_batch_norm.h"

#include <torch/csrc/autograd/custom_function.h>

namespace hsd::model {

namespace {

using torch::autograd::AutogradContext;
using torch::autograd::variable_list;

// One channel-wise view [1, C, 1, 1] of a [C] vector.
torch::Tensor per_channel(const torch::Tensor& v) { return v.view({1, -1, 1, 1}); }

// The normalisation over all replicas' samples, with its own backward (the
// batch statistics couple every sample of the global batch).
struct GlobalBatchNorm : torch::autograd::Function<GlobalBatchNorm> {
  // Returns y; `stats` receives (global mean [C], biased global variance [C], N) in float64.
  static torch::Tensor forward(AutogradContext* ctx, torch::Tensor x, torch::Tensor weight, torch::Tensor bias,
                               ReplicaGroup* group, double eps, torch::Tensor stats_out) {
    const int64_t C = x.size(1), W = group->world_size(), r = group->rank();
    const int64_t n_local = x.numel() / std::max<int64_t>(C, 1);
    // Each replica fills its own row; one sum gathers them all.
    torch::Tensor rows = torch::zeros({W, 2 * C + 1}, x.options().dtype(torch::kFloat64));
    if (n_local > 0) {
      const auto [var_l, mean_l] = torch::var_mean(x, {0, 2, 3}, /*unbiased=*/false);
      rows[r].narrow(0, 0, C).copy_(mean_l);
      rows[r].narrow(0, C, C).copy_(var_l);
    }
    rows[r][2 * C] = double(n_local);
    group->all_reduce_sum_(rows, "batch-norm statistics");
    const torch::Tensor n = rows.select(1, 2 * C).unsqueeze(1);  // [W, 1]
    const double N = n.sum().item<double>();
    if (!(N > 0)) throw std::runtime_error("synchronised batch norm: the global batch is empty");
    const torch::Tensor means = rows.narrow(1, 0, C), vars = rows.narrow(1, C, C);
    const torch::Tensor mean = (n * means).sum(0) / N;
    const torch::Tensor var = (n * (vars + (means - mean).pow(2))).sum(0) / N;
    stats_out.narrow(0, 0, C).copy_(mean);
    stats_out.narrow(0, C, C).copy_(var);
    stats_out[2 * C] = N;

    const torch::Tensor invstd = (var + eps).rsqrt().to(x.scalar_type());
    const torch::Tensor xhat = (x - per_channel(mean.to(x.scalar_type()))) * per_channel(invstd);
    ctx->save_for_backward({xhat, invstd, weight});
    ctx->saved_data["N"] = N;
    ctx->saved_data["group"] = reinterpret_cast<int64_t>(group);
    return xhat * per_channel(weight) + per_channel(bias);
  }

  static variable_list backward(AutogradContext* ctx, variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const torch::Tensor &xhat = saved[0], &invstd = saved[1], &weight = saved[2];
    const double N = ctx->saved_data["N"].toDouble();
    auto* group = reinterpret_cast<ReplicaGroup*>(ctx->saved_data["group"].toInt());
    const torch::Tensor g = grads[0].contiguous();
    const int64_t C = g.size(1);
    const torch::Tensor sum_g = g.sum({0, 2, 3}), sum_gx = (g * xhat).sum({0, 2, 3});
    torch::Tensor sums = torch::cat({sum_g, sum_gx}).to(torch::kFloat64);
    group->all_reduce_sum_(sums, "batch-norm gradient sums");
    const torch::Tensor mean_g = (sums.narrow(0, 0, C) / N).to(g.scalar_type());
    const torch::Tensor mean_gx = (sums.narrow(0, C, C) / N).to(g.scalar_type());
    const torch::Tensor dx =
        per_channel(weight * invstd) * (g - per_channel(mean_g) - xhat * per_channel(mean_gx));
    // γ and β: this replica's share; data-parallel training averages them with
    // the other gradients.
    return {dx, sum_gx, sum_g, torch::Tensor(), torch::Tensor(), torch::Tensor()};
  }
};

}  // namespace

SyncBatchNorm2dImpl::SyncBatchNorm2dImpl(int64_t channels, double eps, double momentum)
    : channels_(channels), eps_(eps), momentum_(momentum) {
  reset();
}

void SyncBatchNorm2dImpl::reset() {
  weight = register_parameter("weight", torch::ones({channels_}));
  bias = register_parameter("bias", torch::zeros({channels_}));
  running_mean = register_buffer("running_mean", torch::zeros({channels_}));
  running_var = register_buffer("running_var", torch::ones({channels_}));
  num_batches_tracked = register_buffer("num_batches_tracked", torch::tensor(int64_t(0), torch::kLong));
}

torch::Tensor SyncBatchNorm2dImpl::forward(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4 && x.size(1) == channels_, "batch norm expects [B, ", channels_, ", H, W], got ", x.sizes());
  if (is_training()) {
    torch::NoGradGuard no_grad;
    num_batches_tracked += 1;
  }
  if (!is_training() || !group_ || group_->world_size() <= 1)  // torch::nn::BatchNorm2d's own call
    return torch::batch_norm(x, weight, bias, running_mean, running_var, is_training(), momentum_, eps_,
                             at::globalContext().userEnabledCuDNN());
  torch::Tensor stats = torch::zeros({2 * channels_ + 1}, torch::kFloat64);
  torch::Tensor y = GlobalBatchNorm::apply(x, weight, bias, group_.get(), eps_, stats);
  // Running statistics of the global batch (unbiased variance, as BatchNorm2d).
  torch::NoGradGuard no_grad;
  const double N = stats[2 * channels_].item<double>();
  const torch::Tensor mean = stats.narrow(0, 0, channels_), var = stats.narrow(0, channels_, channels_);
  running_mean.mul_(1.0 - momentum_).add_(mean.to(running_mean.options()), momentum_);
  running_var.mul_(1.0 - momentum_).add_((var * (N / std::max(N - 1.0, 1.0))).to(running_var.options()), momentum_);
  return y;
}

}  // namespace hsd::model
