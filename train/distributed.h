// Data-parallel training on torch's c10d: a TCP store for the rendezvous
// (rank 0 serves it at MASTER_ADDR:MASTER_PORT) and a Gloo process group for
// the collectives, the engine behind PyTorch's DistributedDataParallel,
// started with torchrun's environment variables (WORLD_SIZE, RANK,
// MASTER_ADDR, MASTER_PORT; LOCAL_WORLD_SIZE for the thread count).
//
// What data parallelism means in hsd (trainer.cpp uses these pieces):
//  - the global batch of step k (train.batch_size patches, their lighting and
//    their noise) is the one a single process draws; rank r takes the slice
//    [r·b, (r+1)·b), b = batch_size / world_size;
//  - each rank's loss is the mean over its slice; the gradients of the network
//    and of the DOE height map are summed over ranks and divided by the world
//    size, which is the gradient of the global batch's mean loss;
//  - batch norm uses the global batch's statistics (model/sync_batch_norm.h);
//  - parameters start identical (broadcast from rank 0), and identical
//    gradients keep them identical.
// So W ranks with batch b reproduce one process with batch W·b up to float
// rounding. A collective that fails (a peer died, so its sockets closed; or it
// stalled past distributed.timeout_s) throws DistributedError naming this rank
// and the collective. A broken group is abandoned rather than torn down
// (destroying a Gloo group with a dead peer can block or abort).
#pragma once
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "model/replica_group.h"

namespace hsd::train {

// Who takes part, from the environment (torchrun's convention).
struct DistributedEnv {
  int world_size = 1, rank = 0;
  int local_world_size = 1;  // ranks on this host (LOCAL_WORLD_SIZE; 1 if unset)
  std::string master_addr;
  int master_port = 0;
  // torchrun's agent already serves the store at MASTER_ADDR:MASTER_PORT
  // (TORCHELASTIC_USE_AGENT_STORE=True): every rank, rank 0 too, is a client.
  bool agent_store = false;
  std::string restart_count = "0";  // TORCHELASTIC_RESTART_COUNT: the agent store's key prefix
  bool enabled() const { return world_size > 1; }
  // None of the variables set (or WORLD_SIZE=1): a single process. InputError
  // naming the variable for a malformed, missing or inconsistent one.
  static DistributedEnv from_environment();
};

// A TCP port on 127.0.0.1 that nobody listens on right now (one-host runs,
// benchmarks and tests pick their MASTER_PORT with it).
int free_local_port();

// What training needs from the ranks it works with. DataParallel is a group
// of W > 1 processes; SingleProcess is a world of one, in which every
// collective leaves its input as it is, so the trainer has one code path.
class Collectives : public model::ReplicaGroup {
 public:
  // A few numbers summed over ranks (loss terms, metric sums), in float64.
  virtual std::vector<double> sum(const std::vector<double>& values, const std::string& what) = 0;
  // Every rank's `value`, indexed by rank.
  virtual std::vector<double> gather(double value, const std::string& what) = 0;
  // Every tensor gets rank 0's values, in place.
  virtual void broadcast_(const std::vector<torch::Tensor>& tensors, const std::string& what) = 0;
  // The gradients of `params` summed over ranks and divided by the world size.
  // A parameter without a gradient counts as zero.
  virtual void average_gradients_(const std::vector<torch::Tensor>& params, const std::string& what) = 0;
  // Waits until every rank got here.
  virtual void barrier(const std::string& what) = 0;
  // Rank 0 runs `work` while the others wait for it.
  virtual void run_on_rank0(const std::string& key, const std::function<void()>& work, const std::string& what) = 0;
  // Seconds spent waiting in collectives so far.
  virtual double seconds_communicating() const = 0;
};

// This process alone: rank 0 of 1; sums, gathers, broadcasts and averages
// return their input, run_on_rank0 runs the work.
class SingleProcess final : public Collectives {
 public:
  int rank() const override { return 0; }
  int world_size() const override { return 1; }
  void all_reduce_sum_(torch::Tensor&, const std::string&) override {}
  std::vector<double> sum(const std::vector<double>& values, const std::string&) override { return values; }
  std::vector<double> gather(double value, const std::string&) override { return {value}; }
  void broadcast_(const std::vector<torch::Tensor>&, const std::string&) override {}
  void average_gradients_(const std::vector<torch::Tensor>&, const std::string&) override {}
  void barrier(const std::string&) override {}
  void run_on_rank0(const std::string&, const std::function<void()>& work, const std::string&) override { work(); }
  double seconds_communicating() const override { return 0.0; }
};

class DataParallel final : public Collectives {
 public:
  // Joins the group: every rank must call this within distributed.timeout_s.
  // InputError when rank 0 cannot serve MASTER_PORT; DistributedError when the
  // ranks do not all meet.
  DataParallel(const DistributedEnv& env, const DistributedConfig& cfg);
  ~DataParallel() override;
  DataParallel(const DataParallel&) = delete;
  DataParallel& operator=(const DataParallel&) = delete;

  int rank() const override;
  int world_size() const override;
  // t summed over ranks, in place (any device; CPU tensors go straight to Gloo).
  void all_reduce_sum_(torch::Tensor& t, const std::string& what) override;
  std::vector<double> sum(const std::vector<double>& values, const std::string& what) override;
  std::vector<double> gather(double value, const std::string& what) override;
  // In flat buckets per dtype.
  void broadcast_(const std::vector<torch::Tensor>& tensors, const std::string& what) override;
  // In flat buckets of about distributed.bucket_mib (one collective each,
  // issued together).
  void average_gradients_(const std::vector<torch::Tensor>& params, const std::string& what) override;
  // Rank 0's `text` under `key`, on every rank (rank 0 publishes it, the others
  // fetch it): e.g. the resolved config, which must agree across ranks.
  std::string from_rank0(const std::string& key, const std::string& text);
  void barrier(const std::string& what) override;
  // The others wait however long the work takes, as long as rank 0 shows a
  // heartbeat; without one for distributed.timeout_s (rank 0 died or hangs)
  // they throw DistributedError. An exception in rank 0's work propagates
  // there (the others then time out).
  void run_on_rank0(const std::string& key, const std::function<void()>& work, const std::string& what) override;

  // Where the time went: seconds spent waiting in collectives, and their count.
  double seconds_communicating() const override;
  int64_t collectives() const;  // how many collectives so far
  std::string describe() const;  // "rank 1 of 2 (127.0.0.1:29500, Gloo)"

 private:
  // Flat per-dtype buckets of `tensors`, one collective each (rank 0's values
  // or the sum over ranks), results scaled by `scale` and copied back.
  void bucketed_(const std::vector<torch::Tensor>& tensors, bool broadcast, double scale, const std::string& what);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace hsd::train
