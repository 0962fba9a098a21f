// What the network needs from data-parallel training, and nothing more: the
// replicas' count, this replica's index and a sum over replicas. train/
// implements it on torch's c10d (train/distributed.h); the model never sees
// the communication library, so it keeps depending on nothing of ours.
#pragma once
#include <string>

#include <torch/types.h>

namespace hsd::model {

class ReplicaGroup {
 public:
  virtual ~ReplicaGroup() = default;
  virtual int rank() const = 0;        // 0 .. world_size() - 1
  virtual int world_size() const = 0;  // 1: a single process
  // Sums `t` elementwise over all replicas, in place. Every replica calls the
  // same sums in the same order (a collective); `what` names it in errors.
  virtual void all_reduce_sum_(torch::Tensor& t, const std::string& what) = 0;
};

}  // namespace hsd::model
