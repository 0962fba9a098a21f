// Batch normalisation (Ioffe & Szegedy 2015) whose batch statistics span the
// global batch of data-parallel training: with a ReplicaGroup of W > 1
// replicas, training-mode forward uses the mean and variance of all replicas'
// samples together and backward the matching global sums, so W replicas with
// batch b compute what one process with batch W·b computes (PyTorch's
// SyncBatchNorm). Alone (no group, or W = 1), and in eval mode, it is exactly
// torch::nn::BatchNorm2d: the same op, the same parameter and buffer names
// (weight, bias, running_mean, running_var, num_batches_tracked), so
// checkpoints and the TorchScript exporter are unchanged.
//
//   forward:  μ = Σ_r n_r μ_r / N,  σ² = Σ_r n_r (σ_r² + (μ_r − μ)²) / N   (per channel)
//             y = (x − μ)/√(σ² + ε) · γ + β
//   backward: ∂x = γ/√(σ²+ε) · (g − Σg/N − x̂ Σ(g x̂)/N)   (sums over all replicas)
// Per-replica statistics are combined in float64 (no E[x²] − E[x]² cancellation).
#pragma once
#include <memory>

#include <torch/torch.h>

#include "model/replica_group.h"

namespace hsd::model {

class SyncBatchNorm2dImpl : public torch::nn::Cloneable<SyncBatchNorm2dImpl> {
 public:
  explicit SyncBatchNorm2dImpl(int64_t channels, double eps = 1e-5, double momentum = 0.1);
  void reset() override;
  // x [B, C, H, W] -> [B, C, H, W].
  torch::Tensor forward(const torch::Tensor& x);
  // nullptr (or a group of one) restores plain batch normalisation.
  void set_replica_group(std::shared_ptr<ReplicaGroup> group) { group_ = std::move(group); }

  torch::Tensor weight, bias, running_mean, running_var, num_batches_tracked;

 private:
  int64_t channels_;
  double eps_, momentum_;
  std::shared_ptr<ReplicaGroup> group_;
};
TORCH_MODULE(SyncBatchNorm2d);

}  // namespace hsd::model
