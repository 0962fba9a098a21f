#include "train/distributed.h"

// c10d's Gloo headers need USE_C10D_GLOO (Torch's CMake config defines it;
// Debian's libtorch_cpu carries the implementation). Only this file sees c10d.
#include <torch/csrc/distributed/c10d/PrefixStore.hpp>
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <map>
#include <thread>
#include <csignal>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "common/error.h"
#include "common/log.h"

namespace hsd::train {

namespace {

using Clock = std::chrono::steady_clock;

const char* getenv_set(const char* name) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' ? v : nullptr;
}

int env_int(const char* name, int lo, int hi) {
  const char* v = getenv_set(name);
  char* end = nullptr;
  errno = 0;
  const long x = std::strtol(v, &end, 10);
  if (errno != 0 || end == v || *end != '\0' || x < lo || x > hi)
    input_error(std::string("environment variable ") + name,
                "\"" + std::string(v) + "\" is not an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return int(x);
}

// The first line of a Gloo/c10d message, without torch's backtrace.
std::string reason(const std::exception& e) {
  std::string s;
  if (const auto* c = dynamic_cast<const c10::Error*>(&e)) s = c->what_without_backtrace();
  else s = e.what();
  const auto nl = s.find('\n');
  return nl == std::string::npos ? s : s.substr(0, nl);
}

bool is_loopback(const std::string& addr) {
  return addr == "localhost" || addr.rfind("127.", 0) == 0 || addr == "::1";
}

}  // namespace

int free_local_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) throw DistributedError("no socket for finding a free port");
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;  // the kernel picks
  socklen_t n = sizeof a;
  const bool ok = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
                  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n) == 0;
  ::close(fd);
  if (!ok) throw DistributedError("could not find a free TCP port on 127.0.0.1");
  return ntohs(a.sin_port);
}

DistributedEnv DistributedEnv::from_environment() {
  DistributedEnv e;
  // WORLD_SIZE decides: clusters often export MASTER_ADDR/PORT for everyone.
  if (!getenv_set("WORLD_SIZE")) {
    if (getenv_set("RANK") || getenv_set("MASTER_ADDR") || getenv_set("MASTER_PORT"))
      log::warn("RANK/MASTER_ADDR/MASTER_PORT are set but WORLD_SIZE is not: running as a single process");
    return e;
  }
  e.world_size = env_int("WORLD_SIZE", 1, 65536);
  if (getenv_set("RANK")) e.rank = env_int("RANK", 0, 65535);
  if (e.world_size == 1) {
    if (e.rank != 0) input_error("environment variable RANK", std::to_string(e.rank) + " is not below WORLD_SIZE 1");
    return e;
  }
  if (!getenv_set("RANK")) input_error("environment variable RANK", "not set (WORLD_SIZE is " + std::to_string(e.world_size) + ")");
  if (e.rank >= e.world_size)
    input_error("environment variable RANK", std::to_string(e.rank) + " is not below WORLD_SIZE " + std::to_string(e.world_size));
  if (!getenv_set("MASTER_ADDR")) input_error("environment variable MASTER_ADDR", "not set (the host of rank 0)");
  e.master_addr = getenv_set("MASTER_ADDR");
  if (!getenv_set("MASTER_PORT")) input_error("environment variable MASTER_PORT", "not set (a free TCP port on rank 0's host)");
  e.master_port = env_int("MASTER_PORT", 1, 65535);
  if (getenv_set("LOCAL_WORLD_SIZE")) e.local_world_size = env_int("LOCAL_WORLD_SIZE", 1, e.world_size);
  const char* agent = getenv_set("TORCHELASTIC_USE_AGENT_STORE");
  e.agent_store = agent != nullptr && std::string(agent) == "True";
  if (const char* restarts = getenv_set("TORCHELASTIC_RESTART_COUNT")) e.restart_count = restarts;
  return e;
}

struct DataParallel::Impl {
  DistributedEnv env;
  DistributedConfig cfg;
  c10::intrusive_ptr<c10d::Store> store;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> pg;
  bool broken = false;
  double seconds = 0.0;
  int64_t count = 0;

  std::string who() const { return "rank " + std::to_string(env.rank) + " of " + std::to_string(env.world_size); }

  // Before issuing a collective: never post work to a failed group.
  void usable(const std::string& what) const {
    if (broken) throw DistributedError(who() + ": " + what + ": the process group already failed");
  }
  // Waits for the works in order; any failure marks the group broken.
  void wait(const std::vector<c10::intrusive_ptr<c10d::Work>>& works, const std::string& what) {
    const auto t0 = Clock::now();
    try {
      for (const auto& w : works) w->wait();
    } catch (const std::exception& e) {
      broken = true;
      throw DistributedError(who() + ": " + what + " failed after " +
                             c10::str(std::chrono::duration<double>(Clock::now() - t0).count()) + " s: " + reason(e) +
                             " (another rank exited, or stalled longer than distributed.timeout_s = " +
                             c10::str(cfg.timeout_s) + " s)");
    }
    seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    count += int64_t(works.size());
  }
};

DataParallel::DataParallel(const DistributedEnv& env, const DistributedConfig& cfg) : impl_(std::make_unique<Impl>()) {
  impl_->env = env;
  impl_->cfg = cfg;
  const auto timeout = std::chrono::milliseconds(int64_t(cfg.timeout_s * 1000.0));
  const std::string where = env.master_addr + ":" + std::to_string(env.master_port);
  // A write to a socket whose peer has exited (Gloo's pairs write without MSG_NOSIGNAL) raises
  // SIGPIPE, whose default action ends the process at once with status 141 and no message (seen:
  // rank 0 killed while rank 1 exited over a config mismatch, about 1 run in 20). Python ignores
  // SIGPIPE at start-up, so PyTorch's ranks see such a write fail instead; ignored here too, it
  // fails with EPIPE and surfaces as a DistributedError (exit 4). Process-wide, from the moment a
  // rank joins: stdout/stderr writes to a closed pipe then fail instead of killing the process.
  std::signal(SIGPIPE, SIG_IGN);
  c10d::TCPStoreOptions so;
  so.port = uint16_t(env.master_port);
  so.isServer = env.rank == 0 && !env.agent_store;
  so.numWorkers = size_t(env.world_size);
  so.waitWorkers = !env.agent_store;
  so.timeout = timeout;
  try {
    impl_->store = c10::make_intrusive<c10d::TCPStore>(env.master_addr, so);
    // torchrun's agent store outlives restarts: keys of this attempt only, as PyTorch does.
    if (env.agent_store)
      impl_->store = c10::make_intrusive<c10d::PrefixStore>("/worker/attempt_" + env.restart_count, impl_->store);
  } catch (const std::exception& e) {
    const std::string r = reason(e);
    if (env.rank == 0 && (r.find("in use") != std::string::npos || r.find("bind") != std::string::npos))
      input_error("environment variable MASTER_PORT", "rank 0 cannot serve " + where + ": " + r + " (choose another port)");
    throw DistributedError(impl_->who() + ": the ranks did not all meet at " + where + " within " + c10::str(cfg.timeout_s) +
                           " s: " + r);
  }
  try {
    auto opts = c10d::ProcessGroupGloo::Options::create(timeout);
    // Loopback for one-host runs; otherwise the interface of GLOO_SOCKET_IFNAME,
    // or the one this host's name resolves to (as PyTorch does).
    if (is_loopback(env.master_addr)) opts->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1"));
    else if (const char* ifname = getenv_set("GLOO_SOCKET_IFNAME"))
      opts->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(ifname));
    else opts->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
    impl_->pg = c10::make_intrusive<c10d::ProcessGroupGloo>(impl_->store, env.rank, env.world_size, opts);
  } catch (const std::exception& e) {
    impl_->broken = true;
    throw DistributedError(impl_->who() + ": joining the Gloo group at " + where + " failed: " + reason(e));
  }
}

DataParallel::~DataParallel() {
  if (impl_ && impl_->broken) {  // abandon: see the header
    if (impl_->pg) impl_->pg.release();
    if (impl_->store) impl_->store.release();
  }
}

int DataParallel::rank() const { return impl_->env.rank; }
int DataParallel::world_size() const { return impl_->env.world_size; }
double DataParallel::seconds_communicating() const { return impl_->seconds; }
int64_t DataParallel::collectives() const { return impl_->count; }
std::string DataParallel::describe() const {
  return impl_->who() + " (" + impl_->env.master_addr + ":" + std::to_string(impl_->env.master_port) + ", Gloo)";
}

void DataParallel::all_reduce_sum_(torch::Tensor& t, const std::string& what) {
  impl_->usable("summing " + what);
  std::vector<at::Tensor> v{t.device().is_cpu() && t.is_contiguous() ? t : t.contiguous().cpu()};
  impl_->wait({impl_->pg->allreduce(v)}, "summing " + what);
  if (!v[0].is_same(t)) t.copy_(v[0]);
}

std::vector<double> DataParallel::sum(const std::vector<double>& values, const std::string& what) {
  torch::Tensor t = torch::tensor(values, torch::kFloat64);
  all_reduce_sum_(t, what);
  return std::vector<double>(t.data_ptr<double>(), t.data_ptr<double>() + t.numel());
}

std::vector<double> DataParallel::gather(double value, const std::string& what) {
  std::vector<double> slots(size_t(world_size()), 0.0);
  slots[size_t(rank())] = value;  // each rank its own slot: the sum gathers them
  return sum(slots, what);
}

namespace {

// Flat CPU buckets of about `bytes`, one dtype each, in the order given.
struct Bucket {
  std::vector<size_t> members;
  torch::Tensor flat;
};

std::vector<Bucket> make_buckets(const std::vector<torch::Tensor>& ts, double bytes) {
  std::vector<Bucket> out;
  std::map<c10::ScalarType, size_t> open;  // dtype -> index of its open bucket
  std::map<c10::ScalarType, double> fill;
  for (size_t i = 0; i < ts.size(); ++i) {
    const auto dt = ts[i].scalar_type();
    const double b = double(ts[i].numel() * ts[i].element_size());
    if (!open.count(dt) || (fill[dt] > 0 && fill[dt] + b > bytes)) {
      open[dt] = out.size();
      fill[dt] = 0;
      out.emplace_back();
    }
    out[open[dt]].members.push_back(i);
    fill[dt] += b;
  }
  for (auto& bk : out) {
    std::vector<torch::Tensor> parts;
    for (size_t i : bk.members) parts.push_back(ts[i].detach().reshape(-1).cpu());
    bk.flat = torch::cat(parts);
  }
  return out;
}

void unpack(const Bucket& bk, const std::vector<torch::Tensor>& ts, double scale) {
  torch::NoGradGuard no_grad;
  int64_t off = 0;
  for (size_t i : bk.members) {
    const int64_t n = ts[i].numel();
    torch::Tensor part = bk.flat.narrow(0, off, n).view(ts[i].sizes());
    if (scale != 1.0) part = part * scale;
    ts[i].copy_(part);
    off += n;
  }
}

}  // namespace

void DataParallel::bucketed_(const std::vector<torch::Tensor>& tensors, bool broadcast, double scale,
                             const std::string& what) {
  if (tensors.empty()) return;
  impl_->usable(what);
  auto buckets = make_buckets(tensors, impl_->cfg.bucket_mib * 1048576.0);
  std::vector<c10::intrusive_ptr<c10d::Work>> works;  // issued together, waited for in order
  for (auto& bk : buckets) {
    std::vector<at::Tensor> v{bk.flat};
    works.push_back(broadcast ? impl_->pg->broadcast(v) : impl_->pg->allreduce(v));
  }
  impl_->wait(works, what + " (" + std::to_string(buckets.size()) + " buckets)");
  for (const auto& bk : buckets) unpack(bk, tensors, scale);
}

void DataParallel::broadcast_(const std::vector<torch::Tensor>& tensors, const std::string& what) {
  bucketed_(tensors, true, 1.0, "broadcasting " + what + " from rank 0");
}

void DataParallel::average_gradients_(const std::vector<torch::Tensor>& params, const std::string& what) {
  std::vector<torch::Tensor> grads;
  for (const auto& p : params) {
    if (!p.grad().defined()) p.mutable_grad() = torch::zeros_like(p);
    grads.push_back(p.grad());
  }
  bucketed_(grads, false, 1.0 / double(world_size()), "averaging " + what);
}


void DataParallel::barrier(const std::string& what) {
  impl_->usable("waiting for all ranks " + what);
  impl_->wait({impl_->pg->barrier()}, "waiting for all ranks " + what);
}

std::string DataParallel::from_rank0(const std::string& key, const std::string& text) {
  try {
    if (rank() == 0) {
      impl_->store->set("hsd/text/" + key, std::vector<uint8_t>(text.begin(), text.end()));
      return text;
    }
    const std::vector<uint8_t> v = impl_->store->get("hsd/text/" + key);  // waits up to the store's timeout
    return std::string(v.begin(), v.end());
  } catch (const std::exception& e) {
    impl_->broken = true;
    throw DistributedError(impl_->who() + ": sharing rank 0's " + key + " failed: " + reason(e));
  }
}

void DataParallel::run_on_rank0(const std::string& key, const std::function<void()>& work, const std::string& what) {
  const std::string done = "hsd/done/" + key, alive = "hsd/alive/" + key;
  if (rank() == 0) {
    // A heartbeat while the work runs, so the others can tell slow from dead.
    std::atomic<bool> stop{false};
    std::thread beat([&] {
      try {
        while (!stop) {
          impl_->store->add(alive, 1);
          for (int i = 0; i < 10 && !stop; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
      } catch (...) {  // a store problem shows at the set below
      }
    });
    try {
      work();
    } catch (...) {
      stop = true;
      beat.join();
      throw;
    }
    stop = true;
    beat.join();
    try {
      impl_->store->set(done, std::vector<uint8_t>{1});
    } catch (const std::exception& e) {
      impl_->broken = true;
      throw DistributedError(impl_->who() + ": announcing that " + what + " is done failed: " + reason(e));
    }
    return;
  }
  // The others: wait while the heartbeat moves; timeout_s without a beat ends it.
  try {
    int64_t last = -1;
    auto last_change = Clock::now();
    for (;;) {
      if (impl_->store->check({done})) return;
      const int64_t beat = impl_->store->add(alive, 0);
      if (beat != last) last = beat, last_change = Clock::now();
      if (std::chrono::duration<double>(Clock::now() - last_change).count() > impl_->cfg.timeout_s)
        throw DistributedError(impl_->who() + ": waiting for rank 0 " + what + ": no sign of life from rank 0 for " +
                               c10::str(impl_->cfg.timeout_s) + " s (distributed.timeout_s)");
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  } catch (const DistributedError&) {
    impl_->broken = true;
    throw;
  } catch (const std::exception& e) {
    impl_->broken = true;
    throw DistributedError(impl_->who() + ": waiting for rank 0 " + what + " failed: " + reason(e) + " (rank 0 exited?)");
  }
}

}  // namespace hsd::train
