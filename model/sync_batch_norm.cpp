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
  // Returns y; `stats_out` receives (global mean [C], biased global variance [C], N) in float64.
  // The passes over x are torch's fused CPU kernels: local statistics
  // (batch_norm_update_stats), normalisation with given statistics (eval-mode
  // batch_norm) and its backward; only the global-statistics term of the
  // backward is added by hand (one in-place pass).
  static torch::Tensor forward(AutogradContext* ctx, torch::Tensor x, torch::Tensor weight, torch::Tensor bias,
                               ReplicaGroup* group, double eps, torch::Tensor stats_out) {
    const int64_t C = x.size(1), W = group->world_size(), r = group->rank();
    const int64_t n_local = x.numel() / std::max<int64_t>(C, 1);
    // Each replica fills its own row; one sum gathers them all.
    torch::Tensor rows = torch::zeros({W, 2 * C + 1}, x.options().dtype(torch::kFloat64));
    if (n_local > 0) {
      const auto [mean_l, var_l] = torch::batch_norm_update_stats(x, {}, {}, 0.0);  // biased variance
      rows[r].narrow(0, 0, C).copy_(mean_l);
      rows[r].narrow(0, C, C).copy_(var_l);
    }
    rows[r][2 * C] = double(n_local);
    group->all_reduce_sum_(rows, "batch-norm statistics");
    const torch::Tensor n = rows.select(1, 2 * C).unsqueeze(1);  // [W, 1]
    const double N = n.sum().item<double>();
    TORCH_CHECK(N > 1, "batch norm needs more than 1 value per channel when training; the global batch has ", N);
    const torch::Tensor means = rows.narrow(1, 0, C), vars = rows.narrow(1, C, C);
    const torch::Tensor mean = (n * means).sum(0) / N;
    const torch::Tensor var = (n * (vars + (means - mean).pow(2))).sum(0) / N;
    stats_out.narrow(0, 0, C).copy_(mean);
    stats_out.narrow(0, C, C).copy_(var);
    stats_out[2 * C] = N;

    const torch::Tensor mean_x = mean.to(x.scalar_type()), var_x = var.to(x.scalar_type());
    ctx->save_for_backward({x, weight, mean_x, var_x});
    ctx->saved_data["N"] = N;
    ctx->saved_data["eps"] = eps;
    ctx->saved_data["group"] = reinterpret_cast<int64_t>(group);
    // (x − μ)/√(σ² + ε) · γ + β with the given μ, σ²: eval-mode batch norm.
    return torch::batch_norm(x, weight, bias, mean_x, var_x, /*training=*/false, 0.0, eps, false);
  }

  static variable_list backward(AutogradContext* ctx, variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const torch::Tensor &x = saved[0], &weight = saved[1], &mean = saved[2], &var = saved[3];
    const double N = ctx->saved_data["N"].toDouble(), eps = ctx->saved_data["eps"].toDouble();
    auto* group = reinterpret_cast<ReplicaGroup*>(ctx->saved_data["group"].toInt());
    const torch::Tensor g = grads[0].contiguous();
    const int64_t C = g.size(1);
    const torch::Tensor invstd = (var + eps).rsqrt();
    // With μ, σ² held fixed: ∂x = g γ/√(σ²+ε), ∂γ = Σ g x̂, ∂β = Σ g (this replica's sums).
    auto [dx, sum_gx, sum_g] = torch::native_batch_norm_backward(g, x, weight, mean, var, mean, invstd, /*train=*/false,
                                                                eps, {true, true, true});
    torch::Tensor sums = torch::cat({sum_g, sum_gx}).to(torch::kFloat64);
    group->all_reduce_sum_(sums, "batch-norm gradient sums");
    // μ and σ² depend on every sample: ∂x −= γ/√(σ²+ε) (Σg/N + x̂ Σ(g x̂)/N), sums over all replicas,
    // = (x − μ) k2 + k1 with k1 = γ invstd Σg/N, k2 = γ invstd² Σ(g x̂)/N.
    const torch::Tensor wi = (weight * invstd).to(torch::kFloat64), inv = invstd.to(torch::kFloat64);
    const torch::Tensor k1 = wi * sums.narrow(0, 0, C) / N, k2 = wi * inv * sums.narrow(0, C, C) / N;
    dx.addcmul_(x, per_channel(k2.to(x.scalar_type())), -1.0);
    dx.add_(per_channel((mean.to(torch::kFloat64) * k2 - k1).to(x.scalar_type())));
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
    const bool alone = !group_ || group_->world_size() <= 1;
    TORCH_CHECK(!alone || x.numel() / channels_ > 1, "batch norm needs more than 1 value per channel when training, got ",
                x.sizes());
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
