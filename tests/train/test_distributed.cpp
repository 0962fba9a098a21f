// Data-parallel training (train/distributed.h, model/sync_batch_norm.h):
// torchrun's environment with clear errors; the collectives (sums,
// broadcasts, bucketed gradient averages) between ranks that run as threads of
// this process over a real TCP store and Gloo group; batch norm over two ranks
// equal to batch norm of the whole batch (float64: output, input and parameter
// gradients, running statistics); noise draws keyed to the global batch; two
// trainer ranks with batch b equal to one trainer with batch 2b; a stalled
// rank ending the other's collective within the timeout; a write to an exited
// peer failing instead of killing the rank (SIGPIPE). Then hsd_train as
// users launch it: two ranks against one process, resume, a killed and a
// stalled rank, bad environments.
#include <catch2/catch.hpp>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <map>
#include <thread>
#include <csignal>
#include <cerrno>
#include <sys/socket.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <torch/csrc/distributed/c10d/TCPStore.hpp>

#include "common/error.h"
#include "common/log.h"
#include "helpers.h"
#include "model/sync_batch_norm.h"
#include "optics/sensor_noise.h"
#include "train/distributed.h"
#include "train/metrics_csv.h"
#include "train/shared_psf.h"
#include "train/trainer.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

using train::free_local_port;

// Sets (or, for nullptr, unsets) environment variables; restores them after.
struct EnvGuard {
  std::map<std::string, std::optional<std::string>> saved;
  void set(const std::string& k, const char* v) {
    if (!saved.count(k)) {
      const char* old = std::getenv(k.c_str());
      saved[k] = old ? std::optional<std::string>(old) : std::nullopt;
    }
    if (v) ::setenv(k.c_str(), v, 1);
    else ::unsetenv(k.c_str());
  }
  ~EnvGuard() {
    for (const auto& [k, v] : saved)
      if (v) ::setenv(k.c_str(), v->c_str(), 1);
      else ::unsetenv(k.c_str());
  }
};

// body(rank, group) on `world` threads, each rank with its own DataParallel
// (one TCP store, one Gloo group). Catch2 is not thread-safe: bodies only
// compute; the caller asserts after the join. The first exception is rethrown.
template <class F>
void run_ranks(int world, const DistributedConfig& cfg, F body, int agent_port = 0) {
  const int port = agent_port > 0 ? agent_port : free_local_port();
  std::vector<std::thread> threads;
  std::vector<std::exception_ptr> errors(static_cast<size_t>(world));
  for (int r = 0; r < world; ++r)
    threads.emplace_back([&, r] {
      try {
        train::DistributedEnv e;
        e.world_size = world, e.rank = r, e.master_addr = "127.0.0.1", e.master_port = port;
        e.agent_store = agent_port > 0;
        auto g = std::make_shared<train::DataParallel>(e, cfg);
        body(r, g);
      } catch (...) {
        errors[size_t(r)] = std::current_exception();
      }
    });
  for (auto& t : threads) t.join();
  for (auto& e : errors)
    if (e) std::rethrow_exception(e);
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// Two ranks: `idle` joins and then takes part in nothing while the other runs
// `f`; returns f's error message and how long f took.
std::pair<std::string, double> error_while_peer_idles(const DistributedConfig& cfg, int idle,
                                                      const std::function<void(train::DataParallel&)>& f) {
  std::string message;
  double seconds = 0;
  std::atomic<bool> done{false};
  run_ranks(2, cfg, [&](int r, std::shared_ptr<train::DataParallel> g) {
    if (r == idle) {
      while (!done) std::this_thread::sleep_for(std::chrono::milliseconds(10));
      return;
    }
    const auto t0 = std::chrono::steady_clock::now();
    message = error_of([&] { f(*g); });
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    done = true;
  });
  return {message, seconds};
}

}  // namespace

TEST_CASE("distributed: torchrun's environment, with one clear error per bad variable", "[distributed]") {
  EnvGuard env;
  for (const char* k : {"WORLD_SIZE", "RANK", "MASTER_ADDR", "MASTER_PORT", "LOCAL_WORLD_SIZE"}) env.set(k, nullptr);
  CHECK_FALSE(train::DistributedEnv::from_environment().enabled());
  env.set("WORLD_SIZE", "1");
  CHECK_FALSE(train::DistributedEnv::from_environment().enabled());
  env.set("WORLD_SIZE", "4");
  env.set("RANK", "3");
  env.set("MASTER_ADDR", "10.0.0.7");
  env.set("MASTER_PORT", "29500");
  env.set("LOCAL_WORLD_SIZE", "2");
  const auto e = train::DistributedEnv::from_environment();
  CHECK(e.enabled());
  CHECK(e.world_size == 4);
  CHECK(e.rank == 3);
  CHECK(e.master_addr == "10.0.0.7");
  CHECK(e.master_port == 29500);
  CHECK(e.local_world_size == 2);
  auto error_naming = [](const char* var) {
    try {
      train::DistributedEnv::from_environment();
    } catch (const InputError& x) {
      return std::string(x.what()).find(var) != std::string::npos;
    }
    return false;
  };
  env.set("RANK", "4");
  CHECK(error_naming("RANK"));
  env.set("RANK", "1");
  env.set("MASTER_PORT", "70000");
  CHECK(error_naming("MASTER_PORT"));
  env.set("MASTER_PORT", "29500");
  env.set("MASTER_ADDR", nullptr);
  CHECK(error_naming("MASTER_ADDR"));
  env.set("MASTER_ADDR", "h");
  env.set("WORLD_SIZE", "two");
  CHECK(error_naming("WORLD_SIZE"));
  // WORLD_SIZE decides: stray RANK/MASTER_* (clusters export them) leave a single process, with a warning.
  env.set("WORLD_SIZE", nullptr);
  const int warnings = log::warning_count();
  CHECK_FALSE(train::DistributedEnv::from_environment().enabled());
  CHECK(log::warning_count() == warnings + 1);
}

TEST_CASE("distributed: the others wait for rank 0's long work while it beats, and not for a silent rank 0",
          "[distributed]") {
  DistributedConfig cfg;
  cfg.timeout_s = 3.0;  // also bounds the rendezvous: not shorter on a loaded machine
  // Work twice as long as the timeout: the heartbeat keeps the others waiting.
  std::vector<double> waited(2);
  run_ranks(2, cfg, [&](int r, std::shared_ptr<train::DataParallel> g) {
    const auto t0 = std::chrono::steady_clock::now();
    g->run_on_rank0("slow", [] { std::this_thread::sleep_for(std::chrono::milliseconds(6000)); }, "to finish slow work");
    waited[size_t(r)] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    g->barrier("after the slow work");  // rank 0 serves the store: it stays until rank 1 saw the result
  });
  CHECK(waited[1] >= 5.9);
  // Rank 0 never starts the work (as if hung before it): rank 1 gives up after the timeout.
  const auto [message, seconds] = error_while_peer_idles(
      cfg, 0, [](train::DataParallel& g) { g.run_on_rank0("never", [] {}, "to provide the dataset"); });
  INFO(message);
  CHECK_THAT(message, Catch::Contains("rank 1 of 2"));
  CHECK_THAT(message, Catch::Contains("no sign of life from rank 0"));
  CHECK(seconds >= 3.0);
  CHECK(seconds < 10.0);
}

TEST_CASE("distributed: sums, broadcasts and bucketed gradient averages between two ranks", "[distributed]") {
  for (double bucket_mib : {1e-4, 25.0}) {  // ~100-byte buckets (one per tensor or less) and one bucket per dtype
    DYNAMIC_SECTION("buckets of " << bucket_mib << " MiB") {
      DistributedConfig cfg;
      cfg.bucket_mib = bucket_mib;
      cfg.timeout_s = 30;
      torch::manual_seed(5);
      const torch::Tensor base32 = torch::randn({70}), base64 = torch::randn({2, 3}, torch::kFloat64);
      std::vector<std::vector<double>> sums(2);
      std::vector<std::vector<torch::Tensor>> bcast(2), grads(2);
      std::vector<int64_t> collectives(2);
      run_ranks(2, cfg, [&](int r, std::shared_ptr<train::DataParallel> g) {
        sums[size_t(r)] = g->sum({double(r + 1), 10.0}, "test numbers");
        // rank-specific values of three dtypes; rank 0's win
        std::vector<torch::Tensor> t{torch::full({5}, float(r + 1)), torch::full({3, 2}, double(7 * (r + 1)), torch::kFloat64),
                                     torch::full({4}, int64_t(100 + r), torch::kInt64)};
        g->broadcast_(t, "test tensors");
        bcast[size_t(r)] = t;
        // gradients (r + 1) · base; one parameter without a gradient
        std::vector<torch::Tensor> p{torch::zeros({70}).requires_grad_(), torch::zeros({2, 3}, torch::kFloat64).requires_grad_(),
                                     torch::zeros({3}).requires_grad_()};
        p[0].mutable_grad() = base32 * float(r + 1);
        p[1].mutable_grad() = base64 * double(r + 1);
        g->average_gradients_(p, "test gradients");
        for (auto& x : p) grads[size_t(r)].push_back(x.grad());
        g->barrier("at the end of the test");
        collectives[size_t(r)] = g->collectives();
      });
      for (int r = 0; r < 2; ++r) {
        CHECK(sums[size_t(r)] == std::vector<double>{3.0, 20.0});
        CHECK(torch::equal(bcast[size_t(r)][0], torch::full({5}, 1.0f)));
        CHECK(torch::equal(bcast[size_t(r)][1], torch::full({3, 2}, 7.0, torch::kFloat64)));
        CHECK(torch::equal(bcast[size_t(r)][2], torch::full({4}, int64_t(100), torch::kInt64)));
        CHECK((grads[size_t(r)][0] - 1.5f * base32).abs().max().item<double>() < 1e-6);
        CHECK((grads[size_t(r)][1] - 1.5 * base64).abs().max().item<double>() < 1e-15);
        CHECK(torch::equal(grads[size_t(r)][2], torch::zeros({3})));
      }
      // Small buckets split the 280 + 48 + 12 bytes of gradients into several collectives.
      if (bucket_mib < 1) CHECK(collectives[0] >= 1 + 2 + 4 + 1);
      else CHECK(collectives[0] == 1 + 3 + 2 + 1);  // sum; broadcast per dtype; gradients per dtype; barrier
    }
  }
}

TEST_CASE("distributed: under torchrun's agent store every rank joins as a client", "[distributed]") {
  EnvGuard env;
  env.set("TORCHELASTIC_USE_AGENT_STORE", "True");
  for (const char* k : {"WORLD_SIZE", "RANK", "MASTER_ADDR", "MASTER_PORT"}) env.set(k, nullptr);
  env.set("WORLD_SIZE", "2"), env.set("RANK", "0"), env.set("MASTER_ADDR", "127.0.0.1"), env.set("MASTER_PORT", "29500");
  CHECK(train::DistributedEnv::from_environment().agent_store);
  // The agent: a store served by someone else on the port (rank 0 serving it too would fail: port in use).
  c10d::TCPStoreOptions so;
  so.port = uint16_t(free_local_port());
  so.isServer = true;
  so.waitWorkers = false;
  so.timeout = std::chrono::milliseconds(30000);
  auto agent = c10::make_intrusive<c10d::TCPStore>("127.0.0.1", so);
  DistributedConfig cfg;
  cfg.timeout_s = 30;
  std::vector<std::vector<double>> sums(2);
  run_ranks(2, cfg, [&](int r, std::shared_ptr<train::DataParallel> g) { sums[size_t(r)] = g->sum({double(r + 1)}, "a number"); },
            so.port);
  CHECK(sums[0] == std::vector<double>{3.0});
  CHECK(sums[1] == std::vector<double>{3.0});
}

TEST_CASE("distributed: batch norm over two ranks equals batch norm of the whole batch (float64)", "[distributed][model]") {
  torch::manual_seed(11);
  const int64_t C = 3;
  const torch::Tensor x = torch::randn({4, C, 5, 6}, torch::kFloat64) * 2.0 + 1.0;
  const torch::Tensor c = torch::randn({4, C, 5, 6}, torch::kFloat64);  // loss = Σ c · y
  const torch::Tensor w0 = torch::rand({C}, torch::kFloat64) + 0.5, b0 = torch::randn({C}, torch::kFloat64);
  // Reference: torch's BatchNorm2d on the whole batch.
  torch::nn::BatchNorm2d ref(C);
  ref->to(torch::kFloat64);
  {
    torch::NoGradGuard ng;
    ref->weight.copy_(w0);
    ref->bias.copy_(b0);
  }
  const torch::Tensor xr = x.clone().requires_grad_();
  const torch::Tensor yr = ref->forward(xr);
  (yr * c).sum().backward();
  // Alone and in eval mode the module is torch's op, bit for bit.
  {
    model::SyncBatchNorm2d alone(C);
    alone->to(torch::kFloat64);
    torch::nn::BatchNorm2d plain(C);
    plain->to(torch::kFloat64);
    CHECK(torch::equal(alone->forward(x), plain->forward(x)));
    CHECK(torch::equal(alone->running_var, plain->running_var));
    alone->eval(), plain->eval();
    CHECK(torch::equal(alone->forward(x), plain->forward(x)));
  }
  // Two ranks with unequal shares (3 + 1 samples): the weighting matters.
  const std::vector<int64_t> lo{0, 3}, n{3, 1};
  std::vector<torch::Tensor> y(2), gx(2), gw(2), gb(2), rm(2), rv(2);
  DistributedConfig cfg;
  cfg.timeout_s = 30;
  run_ranks(2, cfg, [&](int r, std::shared_ptr<train::DataParallel> g) {
    model::SyncBatchNorm2d bn(C);
    bn->to(torch::kFloat64);
    {
      torch::NoGradGuard ng;
      bn->weight.copy_(w0);
      bn->bias.copy_(b0);
    }
    bn->set_replica_group(g);
    const torch::Tensor xs = x.narrow(0, lo[size_t(r)], n[size_t(r)]).clone().requires_grad_();
    y[size_t(r)] = bn->forward(xs);
    (y[size_t(r)] * c.narrow(0, lo[size_t(r)], n[size_t(r)])).sum().backward();
    gx[size_t(r)] = xs.grad(), gw[size_t(r)] = bn->weight.grad(), gb[size_t(r)] = bn->bias.grad();
    rm[size_t(r)] = bn->running_mean.clone(), rv[size_t(r)] = bn->running_var.clone();
  });
  auto diff = [](const torch::Tensor& a, const torch::Tensor& b) { return (a - b).abs().max().item<double>(); };
  CHECK(diff(torch::cat({y[0], y[1]}), yr) < 1e-12);
  CHECK(diff(torch::cat({gx[0], gx[1]}), xr.grad()) < 1e-12);
  CHECK(diff(gw[0] + gw[1], ref->weight.grad()) < 1e-11);  // each rank holds its share; training sums (averages) them
  CHECK(diff(gb[0] + gb[1], ref->bias.grad()) < 1e-11);
  for (int r = 0; r < 2; ++r) {
    CHECK(diff(rm[size_t(r)], ref->running_mean) < 1e-14);
    CHECK(diff(rv[size_t(r)], ref->running_var) < 1e-14);
  }
}

TEST_CASE("distributed: PSFs shared out by bands equal one process's, values and height gradient (float64)",
          "[distributed][optics]") {
  // 4 bands, 3 layers, a 32-sample DOE; float64 throughout.
  const optics::PsfSpec spec = test::make_spec({450e-9, 520e-9, 590e-9, 650e-9}, {0.5, 1.0, 2.0}, 32, 8e-6, 2.4e-4, 9,
                                               6e-6, 0.02, 2, torch::kFloat64);
  const optics::PsfSimulator sim(spec);
  torch::manual_seed(4);
  const torch::Tensor h0 = torch::rand({32, 32}, torch::kFloat64) * 1e-6;
  // What each rank's slice needs (bands, layers), in three cases: overlapping, disjoint, one rank needing nothing.
  using Need = std::pair<std::vector<int64_t>, std::vector<int64_t>>;
  const std::vector<std::array<Need, 2>> cases{{Need{{0, 2}, {0}}, Need{{1, 2, 3}, {0, 2}}},
                                               {Need{{3}, {1}}, Need{{0}, {2}}},
                                               {Need{{0, 1, 2, 3}, {0, 1, 2}}, Need{{}, {}}}};
  for (size_t k = 0; k < cases.size(); ++k) {
    INFO("case " << k);
    std::vector<torch::Tensor> psf(2), grad(2), weights(2);
    for (int r = 0; r < 2; ++r)
      weights[size_t(r)] = torch::rand({int64_t(cases[k][size_t(r)].first.size()), int64_t(cases[k][size_t(r)].second.size()), 9, 9},
                                       torch::kFloat64);
    DistributedConfig cfg;
    cfg.timeout_s = 30;
    run_ranks(2, cfg, [&](int r, std::shared_ptr<train::DataParallel> g) {
      const auto provider = train::make_shared_psf_provider(sim, g);
      const torch::Tensor h = h0.clone().requires_grad_();
      const auto& [bands, layers] = cases[k][size_t(r)];
      const torch::Tensor p = provider(h, layers, bands);
      (p * weights[size_t(r)]).sum().backward();  // each rank's own loss
      psf[size_t(r)] = p.detach();
      grad[size_t(r)] = h.grad();
    });
    // One process: each rank's PSFs computed directly, and the gradient of the sum of both losses.
    const torch::Tensor h = h0.clone().requires_grad_();
    torch::Tensor total = torch::zeros({}, torch::kFloat64);
    for (int r = 0; r < 2; ++r) {
      const auto& [bands, layers] = cases[k][size_t(r)];
      if (bands.empty() || layers.empty()) {
        CHECK(psf[size_t(r)].numel() == 0);
        continue;
      }
      const torch::Tensor ref = sim.compute(h, layers, {}, bands).psf;
      CHECK((psf[size_t(r)] - ref.detach()).abs().max().item<double>() < 1e-14);
      total = total + (ref * weights[size_t(r)]).sum();
    }
    total.backward();
    // Each rank holds its bands' part; their sum is the whole gradient (training then divides by W).
    const torch::Tensor sum = grad[0] + grad[1];
    CHECK((sum - h.grad()).abs().max().item<double>() <= 1e-10 * h.grad().abs().max().item<double>());
  }
}

TEST_CASE("distributed: per-image noise draws do not depend on the rest of the batch", "[distributed][sensor]") {
  optics::NoiseModel m;
  m.std_min = 0.01, m.std_max = 0.05, m.photons_at_saturation = 1000.0;
  const torch::Tensor J = torch::rand({4, 3, 8, 8});
  auto gens = [](int64_t first, int64_t count) {
    std::vector<at::Generator> g;
    for (int64_t i = first; i < first + count; ++i) g.push_back(at::detail::createCPUGenerator(1000 + uint64_t(i)));
    return g;
  };
  const torch::Tensor whole = optics::apply_sensor_noise(J, m, gens(0, 4));
  const torch::Tensor part = optics::apply_sensor_noise(J.narrow(0, 2, 2), m, gens(2, 2));
  CHECK(torch::equal(whole.narrow(0, 2, 2), part));
  CHECK_FALSE(torch::equal(whole[0], whole[1] - J[1] + J[0]));  // images get their own draws
  CHECK_THROWS_AS(optics::apply_sensor_noise(J, m, gens(0, 3)), InputError);
}

namespace {
Config tiny_dp_training(const std::string& root, std::vector<std::string> extra = {}) {
  std::vector<std::string> o{"data.root=\"" + root + "\"", "model.base_width=4", "model.levels=2", "train.batch_size=4",
                             "train.warmup_steps=0", "train.decay=none", "train.val_patches=3", "data.patch_size_px=16",
                             "data.generator.train_scenes=2", "data.generator.val_scenes=1", "data.generator.test_scenes=0",
                             "data.generator.colorchecker=false", "data.generator.width_px=40", "data.generator.height_px=32",
                             "threads=1", "distributed.timeout_s=60", "sensor.noise_std=0.02",
                             "sensor.photons_at_saturation=2000"};  // noise on: its draws must follow the images
  for (auto& e : extra) o.push_back(e);
  return load_config(test::source_path("configs/tiny.json"), o);
}
}  // namespace

TEST_CASE("distributed: two trainer ranks with batch 2 match one trainer with batch 4", "[distributed][train]") {
  const std::string root = (fs::temp_directory_path() / "hsd_test_dp_trainer").string();
  torch::set_num_threads(1);
  const Config cfg = tiny_dp_training(root);
  const int steps = 4;
  train::Trainer one(cfg);
  one.attach_data();
  std::vector<train::Batch> batches;
  std::vector<double> loss1;
  for (int k = 0; k < steps; ++k) {
    batches.push_back(one.train_batch(k));
    loss1.push_back(one.step(batches.back(), k).loss);
  }
  const train::ValStats v1 = one.validate();
  std::vector<std::vector<train::Batch>> slices(2);
  std::vector<std::vector<double>> loss2(2);
  std::vector<train::ValStats> v2(2);
  std::vector<torch::Tensor> h2(2), w2(2);
  run_ranks(2, cfg.distributed, [&](int r, std::shared_ptr<train::DataParallel> g) {
    train::Trainer t(cfg, g);
    t.attach_data();
    for (int k = 0; k < steps; ++k) {
      slices[size_t(r)].push_back(t.train_batch(k));
      loss2[size_t(r)].push_back(t.step(slices[size_t(r)].back(), k).loss);
    }
    v2[size_t(r)] = t.validate();
    h2[size_t(r)] = t.height();
    w2[size_t(r)] = t.net()->parameters().front().detach().clone();
  });
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < steps; ++k) {  // each rank's patches are its slice of the global batch, exactly
      const auto& s = slices[size_t(r)][size_t(k)];
      CHECK(s.first_index == 2 * r);
      CHECK(torch::equal(s.radiance, batches[size_t(k)].radiance.narrow(0, 2 * r, 2)));
      CHECK(torch::equal(s.depth_m, batches[size_t(k)].depth_m.narrow(0, 2 * r, 2)));
      CHECK(loss2[size_t(r)][size_t(k)] == Approx(loss1[size_t(k)]).epsilon(1e-5));
    }
  CHECK(torch::equal(h2[0], h2[1]));  // the ranks stay identical
  CHECK(torch::equal(w2[0], w2[1]));
  const torch::Tensor w1 = one.net()->parameters().front().detach();
  CHECK((w2[0] - w1).abs().max().item<double>() <= 1e-4 * w1.abs().max().item<double>());
  CHECK((h2[0] - one.height()).abs().max().item<double>() <= 1e-4 * one.height().abs().max().item<double>());
  CHECK(v2[0].loss == Approx(v1.loss).epsilon(1e-5));
  CHECK(v2[1].hs_psnr_db == Approx(v1.hs_psnr_db).epsilon(1e-5));
  // The global batch must split evenly.
  CHECK_THROWS_AS(run_ranks(2, cfg.distributed,
                            [&](int, std::shared_ptr<train::DataParallel> g) { train::Trainer t(tiny_dp_training(root, {"train.batch_size=3"}), g); }),
                  InputError);
}

TEST_CASE("distributed: a rank that stops answering ends the other's collective within the timeout", "[distributed]") {
  DistributedConfig cfg;
  cfg.timeout_s = 3.0;  // also bounds the rendezvous: not shorter on a loaded machine
  // Rank 1 joins, then never takes part.
  const auto [message, seconds] = error_while_peer_idles(cfg, 1, [](train::DataParallel& g) { g.sum({1.0}, "the loss of step 7"); });
  INFO(message);
  CHECK_THAT(message, Catch::Contains("rank 0 of 2"));
  CHECK_THAT(message, Catch::Contains("the loss of step 7"));
  CHECK(seconds >= 2.5);
  CHECK(seconds < 12.0);
}

TEST_CASE("distributed: once a rank joins, a write to an exited peer's socket fails with EPIPE instead of killing the rank",
          "[distributed]") {
  // hsd_train's rank 0 was once ended by SIGPIPE (status 141, no message) while its peer exited over a
  // config mismatch. The default disposition is restored first, so the join itself must change it.
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  REQUIRE(::sigaction(SIGPIPE, &dfl, nullptr) == 0);
  DistributedConfig cfg;
  cfg.timeout_s = 30;
  run_ranks(2, cfg, [](int, std::shared_ptr<train::DataParallel> g) { g->barrier("after joining"); });
  struct sigaction now {};
  REQUIRE(::sigaction(SIGPIPE, nullptr, &now) == 0);
  REQUIRE(now.sa_handler == SIG_IGN);  // only then is the write below safe for this test binary
  int fds[2];
  REQUIRE(::socketpair(AF_UNIX, SOCK_STREAM, 0, fds) == 0);
  ::close(fds[1]);  // the peer is gone
  const char byte = 'x';
  const ssize_t n = ::write(fds[0], &byte, 1);
  const int err = errno;
  ::close(fds[0]);
  CHECK(n == -1);
  CHECK(err == EPIPE);
}

// ---- hsd_train as users launch it -----------------------------------------

namespace {
const std::string kTinyRun =
    " --config configs/tiny.json --set model.base_width=4 --set model.levels=2 --set train.batch_size=4"
    " --set train.warmup_steps=0 --set train.decay=none --set train.val_patches=3 --set train.val_every=3"
    " --set train.log_every=1 --set train.checkpoint_every=2 --set data.patch_size_px=16"
    " --set data.generator.train_scenes=2 --set data.generator.val_scenes=1 --set data.generator.test_scenes=0"
    " --set data.generator.colorchecker=false --set data.generator.width_px=40 --set data.generator.height_px=32"
    " --set threads=1 --set sensor.noise_std=0.02 --set sensor.photons_at_saturation=2000";

// step -> (train_loss, val_loss) of a metrics.csv (NaN where empty).
std::map<int, std::pair<double, double>> losses(const fs::path& csv) {
  std::map<int, std::pair<double, double>> out;
  const train::CsvTable t = train::read_csv_table(csv.string());
  for (size_t r = 0; r < t.rows.size(); ++r) out[int(t.number(r, "step"))] = {t.number(r, "train_loss"), t.number(r, "val_loss")};
  return out;
}

// Same steps, and losses within `rel` of each other. A run that stopped at
// step s validated there too (`extra_val_step`), the uninterrupted one did not.
void check_same_curve(const std::map<int, std::pair<double, double>>& a, const std::map<int, std::pair<double, double>>& b,
                      double rel, int extra_val_step = -1) {
  REQUIRE(a.size() == b.size());
  for (const auto& [step, l] : a) {
    REQUIRE(b.count(step));
    const auto& m = b.at(step);
    INFO("step " << step);
    CHECK(std::isnan(l.first) == std::isnan(m.first));
    if (!std::isnan(l.first)) CHECK(std::fabs(l.first - m.first) <= rel * std::fabs(l.first));
    if (step == extra_val_step) continue;
    CHECK(std::isnan(l.second) == std::isnan(m.second));
    if (!std::isnan(l.second)) CHECK(std::fabs(l.second - m.second) <= rel * std::fabs(l.second));
  }
}

std::string launcher(const std::string& args) {
  return "cd " + std::string(HSD_SOURCE_DIR) + " && HSD_TRAIN_BIN=" + std::string(HSD_BIN_DIR) +
         "/hsd_train scripts/launch_distributed.sh " + args;
}
}  // namespace

TEST_CASE("hsd_train: two ranks match one process with the same global batch, and resume", "[app][distributed]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_dp_app";
  fs::remove_all(base);
  const std::string run_args = kTinyRun + " --set data.root=" + (base / "data").string();
  const test::Run one = test::run("hsd_train" + run_args + " --set train.steps=6 --out " + (base / "one").string());
  INFO(one.err);
  REQUIRE(one.code == 0);
  const auto [out2, code2] =
      test::capture(launcher("--nproc 2 -- " + run_args + " --set train.steps=6 --out " + (base / "two").string() + " 2>&1"));
  INFO(out2);
  REQUIRE(code2 == 0);
  CHECK_THAT(out2, Catch::Contains("2 ranks x 2 patches = global batch 4"));
  for (const char* f : {"metrics.csv", "curves.png", "config.json", "checkpoints/last.pt", "val/step_000006_reconstructions.png"})
    CHECK(fs::exists(base / "two" / f));
  const auto curve1 = losses(base / "one" / "metrics.csv");
  CHECK(curve1.size() == 7);
  check_same_curve(curve1, losses(base / "two" / "metrics.csv"), 1e-3);
  // Two ranks stopped at step 4 and resumed to 6: the same curve again.
  const std::string three = (base / "three").string();
  const auto [o3, c3] = test::capture(launcher("--nproc 2 -- " + run_args + " --set train.steps=4 --out " + three + " 2>&1"));
  INFO(o3);
  REQUIRE(c3 == 0);
  const auto [o4, c4] =
      test::capture(launcher("--nproc 2 -- " + run_args + " --set train.steps=6 --out " + three + " --resume 2>&1"));
  INFO(o4);
  REQUIRE(c4 == 0);
  CHECK_THAT(o4, Catch::Contains("resuming from"));
  check_same_curve(curve1, losses(base / "three" / "metrics.csv"), 1e-3, 4);
}

TEST_CASE("hsd_train: a killed or stalled rank makes the other exit with an error, and rank 1 writes nothing",
          "[app][distributed]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_dp_fail";
  fs::remove_all(base);
  const std::string bin = std::string(HSD_BIN_DIR) + "/hsd_train";
  const std::string args = kTinyRun + " --set data.root=" + (base / "data").string() + " --set train.steps=100000";
  // Rank 0 and rank 1 started by hand (different --out, so rank 1's silence shows); once rank 0 wrote a
  // checkpoint, the victim gets `signal`; the script prints the survivor's exit code and how long it took
  // after the signal (ms).
  auto scenario = [&](const std::string& name, const std::string& signal, int victim, double timeout_s) {
    const fs::path dir = base / name;
    const int survivor = 1 - victim;
    const std::string env = "WORLD_SIZE=2 MASTER_ADDR=127.0.0.1 MASTER_PORT=" + std::to_string(free_local_port());
    const std::string sets = args + " --set distributed.timeout_s=" + std::to_string(timeout_s);
    std::string script = "cd " + std::string(HSD_SOURCE_DIR) + "\n";
    for (int r = 0; r < 2; ++r)
      script += env + " RANK=" + std::to_string(r) + " " + bin + sets + " --out " + (dir / ("r" + std::to_string(r))).string() +
                " 2> " + (dir / ("r" + std::to_string(r) + ".err")).string() + " > /dev/null &\np" + std::to_string(r) + "=$!\n";
    script += "for i in $(seq 1 600); do [ -f " + (dir / "r0/checkpoints/last.pt").string() +
              " ] && break; sleep 0.1; done\nkill -" + signal + " $p" + std::to_string(victim) + "\nt0=$(date +%s%N)\nwait $p" +
              std::to_string(survivor) + "\nc=$?\nt1=$(date +%s%N)\nkill -9 $p" + std::to_string(victim) +
              " 2>/dev/null\nwait $p" + std::to_string(victim) + " 2>/dev/null\necho \"$c $(( (t1 - t0) / 1000000 ))\"\n";
    fs::create_directories(dir);
    std::ofstream(dir / "scenario.sh") << script;
    const auto [out, code] = test::capture("bash " + (dir / "scenario.sh").string());
    std::ifstream ef(dir / ("r" + std::to_string(survivor) + ".err"));
    const std::string err((std::istreambuf_iterator<char>(ef)), std::istreambuf_iterator<char>());
    INFO(name << ": " << out << "\n" << err);
    std::istringstream ss(out);
    int rc = -1;
    double ms = -1;
    ss >> rc >> ms;
    const double secs = ms / 1000.0;
    CHECK(rc == 4);
    CHECK_THAT(err, Catch::Contains("rank " + std::to_string(survivor) + " of 2"));
    CHECK_THAT(err, Catch::Contains("failed"));
    CHECK(secs < timeout_s + 10.0);
    CHECK(fs::exists(dir / "r0" / "checkpoints" / "last.pt"));
    CHECK_FALSE(fs::exists(dir / "r1"));  // rank 1 wrote nothing
    return secs;
  };
  // A dead rank's sockets close: the other stops at once, long before the timeout.
  CHECK(scenario("killed_rank1", "9", 1, 120.0) < 10.0);
  CHECK(scenario("killed_rank0", "9", 0, 120.0) < 10.0);  // rank 0 also served the store
  // Alive but silent: the timeout (10 s: it also bounds the rendezvous and rank 0's picture writing).
  CHECK(scenario("stalled", "STOP", 1, 10.0) >= 5.0);
}

TEST_CASE("hsd_train: bad distributed settings exit 2 with one line naming the variable or key", "[app][distributed]") {
  const fs::path base = fs::temp_directory_path() / "hsd_test_dp_bad";
  fs::remove_all(base);
  const std::string args = kTinyRun + " --set data.root=" + (base / "data").string() + " --set train.steps=2 --out " + base.string();
  auto count_lines = [](const std::string& s) { return std::count(s.begin(), s.end(), '\n'); };
  const std::string bin = std::string(HSD_BIN_DIR) + "/hsd_train";
  auto run_env = [&](const std::string& env, const std::string& extra) {
    return test::capture("cd " + std::string(HSD_SOURCE_DIR) + " && env " + env + " " + bin + args + extra +
                         " 2>&1 >/dev/null; echo \"exit=$?\"");
  };
  auto [o1, c1] = run_env("WORLD_SIZE=2 RANK=2 MASTER_ADDR=127.0.0.1 MASTER_PORT=29500", "");
  CHECK_THAT(o1, Catch::Contains("exit=2"));
  CHECK_THAT(o1, Catch::Contains("RANK"));
  CHECK(count_lines(o1) == 2);
  auto [o2, c2] = run_env("WORLD_SIZE=2 RANK=0 MASTER_ADDR=127.0.0.1 MASTER_PORT=29500", " --set train.batch_size=3");
  CHECK_THAT(o2, Catch::Contains("exit=2"));
  CHECK_THAT(o2, Catch::Contains("train.batch_size"));
  CHECK(count_lines(o2) == 2);
  // Ranks with different configs: the odd one out names the key; its peer reports the lost rank.
  const std::string o3 = test::two_rank_train(args, args + " --set train.lr_net=0.001");
  INFO(o3);
  CHECK_THAT(o3, Catch::Contains("rank1=2"));
  CHECK_THAT(o3, Catch::Contains("train.lr_net"));
  CHECK_THAT(o3, Catch::Contains("rank0=4"));
  // One rank resuming while the other starts afresh would run other collectives: refused by name.
  const std::string ckdir = (base / "ck").string();
  REQUIRE(test::run("hsd_train" + kTinyRun + " --set data.root=" + (base / "data").string() + " --set train.steps=2 --out " +
                    ckdir).code == 0);
  const std::string ck_args = kTinyRun + " --set data.root=" + (base / "data").string() + " --set train.steps=4 --out " + ckdir;
  const std::string o6 = test::two_rank_train(ck_args, ck_args + " --resume");
  INFO(o6);
  CHECK_THAT(o6, Catch::Contains("rank1=2"));
  CHECK_THAT(o6, Catch::Contains("--resume"));
  CHECK_THAT(o6, Catch::Contains("rank0=4"));
  // The launcher refuses what it cannot run, and passes a rank's failure on.
  const auto [o4, c4] = test::capture(launcher("--nproc 0 -- --config x 2>&1"));
  CHECK(c4 == 2);
  const auto [o5, c5] = test::capture(launcher("--nproc 2 -- " + args + " --set train.batch_size=3 2>&1"));
  CHECK(c5 == 2);
  CHECK_THAT(o5, Catch::Contains("train.batch_size"));
  // The quick job's rank count (scripts/quick_job.sh) is checked before anything runs.
  const auto [o7, c7] = test::capture("cd " + std::string(HSD_SOURCE_DIR) + " && HSD_QUICK_RANKS=two bash scripts/quick_job.sh 2>&1");
  CHECK(c7 == 2);
  CHECK_THAT(o7, Catch::Contains("HSD_QUICK_RANKS"));
  CHECK(count_lines(o7) == 1);
}

TEST_CASE("hsd_bench dist: one process against two ranks and the floor, as one JSON object", "[app][distributed][bench]") {
  const std::string sets =
      " --config configs/tiny.json --set model.base_width=4 --set model.levels=2 --set data.render_margin_px=4 --patch 16 --repeats 1";
  const auto [out, code] = test::capture("cd " + std::string(HSD_SOURCE_DIR) + " && " + std::string(HSD_BIN_DIR) +
                                         "/hsd_bench dist --json --ranks 2 --batch 2" + sets + " 2>/dev/null");
  INFO(out);
  REQUIRE(code == 0);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);  // exactly one object: the ranks' output went elsewhere
  const auto j = nlohmann::json::parse(out);
  for (const char* k : {"seconds_per_step_one_process", "seconds_per_step_ranks_sync_bn", "seconds_per_step_ranks_local_bn",
                        "seconds_per_step_independent", "gradient_average_bucketed_seconds", "gradient_average_per_tensor_seconds"})
    CHECK(j.at(k).get<double>() > 0.0);
  CHECK(j.at("ranks").get<int>() == 2);
  // Patches rendered with the config's scene margin, as training and hsd_bench train render them.
  const Config cfg =
      load_config(test::source_path("configs/tiny.json"), {"model.base_width=4", "model.levels=2", "data.render_margin_px=4"});
  REQUIRE(train::render_margin_px(cfg) == 4);
  CHECK(j.at("margin").get<int64_t>() == 4);
  CHECK(j.at("fraction_in_collectives_sync_bn").get<double>() > 0.0);
  // 25-MiB buckets: one collective per dtype (the float32 network, the float64 height map); per tensor: one each.
  CHECK(j.at("gradient_average_bucketed_collectives").get<int>() == 2);
  CHECK(j.at("gradient_average_per_tensor_collectives").get<int>() == j.at("gradient_tensors").get<int>());
  const test::Run bad = test::run("hsd_bench dist --ranks 2 --batch 3" + sets);
  CHECK(bad.code == 2);
  CHECK_THAT(bad.err, Catch::Contains("--batch"));
}
