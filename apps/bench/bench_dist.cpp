// hsd_bench dist: data-parallel training against one process, side by side
// in one run, on the same global batch (--batch patches of --patch px, each
// rendered with the config's scene margin around it as training renders them
// and as hsd_bench train does; the config's optics and network):
//   - one process with all the threads;
//   - --ranks local ranks (Gloo over loopback, cores / ranks threads each):
//     the defaults (batch norm over the global batch, PSFs shared out by
//     bands), every rank computing all PSFs, and batch norm per rank;
//   - the same ranks' shares as independent processes at once, without any
//     communication (each computing all PSFs): what two processes cost on
//     this machine before any collective;
//   - the gradient average alone: flat buckets against one collective per tensor.
// The ranks are this binary started again with hidden flags (--child-mode,
// --child-result); their figures come back through a JSON file.
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <thread>

#include <torch/torch.h>

#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "train/distributed.h"
#include "train/trainer.h"

extern char** environ;

namespace hsd::bench {

namespace {

train::Batch slice(const train::Batch& b, int64_t first, int64_t n) {
  return {b.radiance.narrow(0, first, n).contiguous(), b.depth_m.narrow(0, first, n).contiguous(), first};
}

// One rank (or one independent copy of a rank's work, mode "solo").
int run_child(Config cfg, const AppArgs& args, int64_t batch, int64_t patch, int repeats) {
  const std::string mode = args.option("--child-mode", ""), result = args.option("--child-result", "");
  const int64_t ranks = args.integer("--ranks", 2);
  std::shared_ptr<train::DataParallel> group;
  int64_t rank = args.integer("--child-rank", 0);
  if (mode != "solo") {
    cfg.distributed.sync_batch_norm = mode != "nosync";
    cfg.distributed.split_psf = mode != "nosplit";
    const train::DistributedEnv env = train::DistributedEnv::from_environment();
    group = std::make_shared<train::DataParallel>(env, cfg.distributed);
    rank = group->rank();
  }
  cfg.train.batch_size = mode == "solo" ? batch / ranks : batch;
  train::Trainer t(cfg, group);
  const train::Batch b = slice(striped_batch(cfg, batch, patch + 2 * train::render_margin_px(cfg)), rank * (batch / ranks), batch / ranks);
  give_batch_spectral_prior(t, cfg, b);
  int64_t k = 0;
  t.step(b, k++);  // warm-up
  const double comm0 = group ? group->seconds_communicating() : 0.0;
  const auto t0 = std::chrono::steady_clock::now();
  const double step_s = median_seconds([&] { t.step(b, k++); }, repeats, false);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  Json j{{"seconds_per_step", step_s}};
  if (group) {
    j["fraction_in_collectives"] = (group->seconds_communicating() - comm0) / std::max(wall, 1e-9);
    // The gradient average alone, on the gradients the last step left.
    std::vector<torch::Tensor> params = t.net()->parameters();
    params.push_back(t.doe().parameter());
    double mib = 0;
    for (const auto& p : params) mib += double(p.numel() * p.element_size()) / 1048576.0;
    auto timed = [&](const std::function<void()>& average) {
      const int64_t c0 = group->collectives();
      const double s = median_seconds(average, repeats);
      return std::make_pair(s, (group->collectives() - c0) / (repeats + 1));
    };
    // Training's buckets (distributed.bucket_mib) against one collective per tensor.
    const auto [bucketed_s, bucketed_n] = timed([&] { group->average_gradients_(params, "benchmark gradients"); });
    const auto [per_tensor_s, per_tensor_n] = timed([&] {
      for (const auto& p : params) {
        torch::Tensor g = p.grad();
        if (!g.defined()) continue;  // a frozen DOE has no gradient (average_gradients_ counts it as zero)
        group->all_reduce_sum_(g, "benchmark gradient");
        g.div_(double(group->world_size()));
      }
    });
    j["gradient_mib"] = mib;
    j["tensors"] = params.size();
    j["bucketed_seconds"] = bucketed_s, j["bucketed_collectives"] = bucketed_n;
    j["per_tensor_seconds"] = per_tensor_s, j["per_tensor_collectives"] = per_tensor_n;
  }
  if (rank == 0 || mode == "solo") write_text_file(result + (mode == "solo" ? "." + std::to_string(rank) : ""), j.dump());
  return 0;
}

// Starts this binary `ranks` times in `mode` and waits; the figures of rank 0
// (or, for "solo", the slowest copy).
Json spawn_children(const std::string& config_file, const AppArgs& args, const std::string& mode, int64_t ranks, int threads,
                    const std::string& result) {
  const int port = train::free_local_port();
  std::vector<pid_t> pids;
  for (int64_t r = 0; r < ranks; ++r) {
    std::vector<std::string> a{"/proc/self/exe", "dist", "--json", "--config", config_file, "--threads", std::to_string(threads),
                               "--ranks", std::to_string(ranks), "--child-mode", mode, "--child-result", result,
                               "--child-rank", std::to_string(r)};
    for (const char* f : {"--patch", "--batch", "--repeats"})
      if (args.options.count(f)) a.push_back(f), a.push_back(args.options.at(f));
    std::vector<std::string> e;
    for (char** v = environ; *v; ++v) {
      const std::string s = *v;
      if (s.rfind("WORLD_SIZE=", 0) && s.rfind("RANK=", 0) && s.rfind("MASTER_", 0) && s.rfind("LOCAL_WORLD_SIZE=", 0) &&
          s.rfind("TORCHELASTIC_", 0))  // the ranks are ours, not an outer launcher's
        e.push_back(s);
    }
    if (mode != "solo")
      for (const std::string& s : {"WORLD_SIZE=" + std::to_string(ranks), "RANK=" + std::to_string(r), std::string("MASTER_ADDR=127.0.0.1"),
                                   "MASTER_PORT=" + std::to_string(port), "LOCAL_WORLD_SIZE=" + std::to_string(ranks)})
        e.push_back(s);
    std::vector<char*> argv, envp;
    for (auto& s : a) argv.push_back(s.data());
    for (auto& s : e) envp.push_back(s.data());
    argv.push_back(nullptr), envp.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);  // the children's JSON goes to the file
    pid_t pid = 0;
    const int rc = posix_spawn(&pid, "/proc/self/exe", &fa, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("hsd_bench dist: could not start a rank (posix_spawn error " + std::to_string(rc) + ")");
    pids.push_back(pid);
  }
  int failed = 0;
  for (pid_t p : pids) {
    int status = 0;
    waitpid(p, &status, 0);
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) failed = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  if (failed) throw std::runtime_error("hsd_bench dist: a " + mode + " rank failed (exit " + std::to_string(failed) + "); its stderr is above");
  auto read = [](const std::string& path) { return Json::parse(std::ifstream(path)); };
  if (mode != "solo") return read(result);
  Json slowest;
  for (int64_t r = 0; r < ranks; ++r) {
    const Json j = read(result + "." + std::to_string(r));
    if (slowest.is_null() || j["seconds_per_step"].get<double>() > slowest["seconds_per_step"].get<double>()) slowest = j;
  }
  return slowest;
}

// What was measured: the one-process step and each multi-rank mode's slowest rank.
struct DistRuns {
  int cores = 0, all_threads = 0, rank_threads = 0;
  double one_s = 0;
  Json sync, nosplit, nosync, solo;
};

void dist_report(const Config& cfg, int64_t patch, int64_t batch, int64_t ranks, const DistRuns& r, BenchOutput& out) {
  const int cores = r.cores, all_threads = r.all_threads, rank_threads = r.rank_threads;
  const double one_s = r.one_s;
  const Json &sync = r.sync, &nosplit = r.nosplit, &nosync = r.nosync, &solo = r.solo;
  const double sync_s = sync["seconds_per_step"], nosplit_s = nosplit["seconds_per_step"], nosync_s = nosync["seconds_per_step"],
               solo_s = solo["seconds_per_step"];
  out.json = Json{{"bench", "dist"},
                  {"threads", all_threads},
                  {"cores", cores},
                  {"ranks", ranks},
                  {"threads_per_rank", rank_threads},
                  {"patch", patch},
                  {"margin", train::render_margin_px(cfg)},
                  {"batch", batch},
                  {"bands", cfg.optics.wavelengths_nm.size()},
                  {"depths", cfg.optics.depths_m.size()},
                  {"base_width", cfg.model.base_width},
                  {"levels", cfg.model.levels},
                  {"seconds_per_step_one_process", one_s},
                  {"seconds_per_step_ranks_sync_bn", sync_s},
                  {"seconds_per_step_ranks_psf_per_rank", nosplit_s},
                  {"seconds_per_step_ranks_local_bn", nosync_s},
                  {"seconds_per_step_independent", solo_s},
                  {"fraction_in_collectives_sync_bn", sync["fraction_in_collectives"]},
                  {"fraction_in_collectives_psf_per_rank", nosplit["fraction_in_collectives"]},
                  {"fraction_in_collectives_local_bn", nosync["fraction_in_collectives"]},
                  {"gradient_mib", sync["gradient_mib"]},
                  {"gradient_tensors", sync["tensors"]},
                  {"gradient_average_bucketed_seconds", sync["bucketed_seconds"]},
                  {"gradient_average_bucketed_collectives", sync["bucketed_collectives"]},
                  {"gradient_average_per_tensor_seconds", sync["per_tensor_seconds"]},
                  {"gradient_average_per_tensor_collectives", sync["per_tensor_collectives"]}};
  char buf[1800];
  std::snprintf(
      buf, sizeof buf,
      "data-parallel training step: global batch %lld of %lld px rendered with %lld px of scene around them, %zu bands, %zu depths, U-Net width %lld x %lld levels; "
      "%d cores\n"
      "one process, %d threads                          %7.3f s/step\n"
      "%lld ranks x %d threads (global batch norm,\n"
      "  PSFs shared out by bands: the defaults)        %7.3f s/step  %.2fx  %4.1f%% in collectives\n"
      "%lld ranks, every rank computing all PSFs         %7.3f s/step  %.2fx  %4.1f%% in collectives\n"
      "%lld ranks x %d threads, batch norm per rank      %7.3f s/step  %.2fx  %4.1f%% in collectives\n"
      "%lld independent processes, a rank's share each   %7.3f s/step  %.2fx  (all PSFs each, no communication)\n"
      "gradient average, %.1f MiB in %lld tensors: %lld bucket(s) %.4f s, one collective per tensor %.4f s (%.1fx)\n",
      (long long)batch, (long long)patch, (long long)train::render_margin_px(cfg), cfg.optics.wavelengths_nm.size(), cfg.optics.depths_m.size(),
      (long long)cfg.model.base_width, (long long)cfg.model.levels, cores, all_threads, one_s, (long long)ranks, rank_threads,
      sync_s, one_s / sync_s, 100.0 * sync["fraction_in_collectives"].get<double>(), (long long)ranks, nosplit_s,
      one_s / nosplit_s, 100.0 * nosplit["fraction_in_collectives"].get<double>(), (long long)ranks, rank_threads, nosync_s,
      one_s / nosync_s, 100.0 * nosync["fraction_in_collectives"].get<double>(), (long long)ranks, solo_s, one_s / solo_s,
      sync["gradient_mib"].get<double>(), (long long)sync["tensors"].get<int64_t>(),
      (long long)sync["bucketed_collectives"].get<int64_t>(), sync["bucketed_seconds"].get<double>(),
      sync["per_tensor_seconds"].get<double>(),
      sync["per_tensor_seconds"].get<double>() / std::max(1e-12, sync["bucketed_seconds"].get<double>()));
  out.text = buf;
}

}  // namespace

int bench_dist(Config cfg, const AppArgs& args, BenchOutput& out) {
  const int64_t patch = args.integer("--patch", 128), batch = args.integer("--batch", 4), ranks = args.integer("--ranks", 2);
  const int repeats = int(args.integer("--repeats", 3));
  if (patch < 16 || patch > 2048) input_error("--patch", "must be in [16, 2048]");
  if (ranks < 2 || ranks > 64) input_error("--ranks", "must be in [2, 64]");
  if (batch < ranks || batch % ranks != 0 || batch > 256)
    input_error("--batch", "must be a multiple of --ranks " + std::to_string(ranks) + " in [" + std::to_string(ranks) + ", 256]");
  if (repeats < 1) input_error("--repeats", "must be >= 1");
  if (args.has("--child-mode")) return run_child(cfg, args, batch, patch, repeats);

  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  const int all_threads = torch::get_num_threads();
  const int rank_threads = std::max(1, cores / int(ranks));
  // One process, all threads.
  cfg.train.batch_size = batch;
  double one_s = 0;
  {
    log::info("one process, " + std::to_string(all_threads) + " threads ...");
    train::Trainer t(cfg);
    const train::Batch b = striped_batch(cfg, batch, patch + 2 * train::render_margin_px(cfg));
    give_batch_spectral_prior(t, cfg, b);
    int64_t k = 0;
    one_s = median_seconds([&] { t.step(b, k++); }, repeats);
  }
  // The ranks, started as child processes on the resolved config.
  const auto tmp = std::filesystem::temp_directory_path() / ("hsd_bench_dist_" + std::to_string(::getpid()));
  std::filesystem::create_directories(tmp);
  const std::string config_file = (tmp / "config.json").string();
  Json resolved = cfg.resolved;
  resolved["distributed"]["timeout_s"] = std::min(cfg.distributed.timeout_s, 60.0);  // a failed rank ends its peer soon
  write_text_file(config_file, resolved.dump(2));
  Json sync, nosplit, nosync, solo;
  log::info(std::to_string(ranks) + " ranks x " + std::to_string(rank_threads) + " threads, the defaults ...");
  sync = spawn_children(config_file, args, "sync", ranks, rank_threads, (tmp / "sync.json").string());
  log::info(std::to_string(ranks) + " ranks, every rank computing all PSFs ...");
  nosplit = spawn_children(config_file, args, "nosplit", ranks, rank_threads, (tmp / "nosplit.json").string());
  log::info(std::to_string(ranks) + " ranks, batch norm per rank ...");
  nosync = spawn_children(config_file, args, "nosync", ranks, rank_threads, (tmp / "nosync.json").string());
  log::info(std::to_string(ranks) + " independent processes of one rank's share each (no communication) ...");
  solo = spawn_children(config_file, args, "solo", ranks, rank_threads, (tmp / "solo.json").string());
  std::filesystem::remove_all(tmp);

  const DistRuns runs{cores, all_threads, rank_threads, one_s, sync, nosplit, nosync, solo};
  dist_report(cfg, patch, batch, ranks, runs, out);
  return 0;
}

}  // namespace hsd::bench
