// hsd_train: joint end-to-end training of the DOE and the reconstruction
// network (train/trainer.h). Writes DIR/metrics.csv, DIR/curves.png,
// DIR/val_psnr.png, DIR/val/ (reconstructions, depth maps, error maps and the
// PSF atlas at each validation), DIR/checkpoints/last.pt and DIR/config.json.
// --resume continues from DIR/checkpoints/last.pt exactly. With torchrun's
// WORLD_SIZE, RANK, MASTER_ADDR, MASTER_PORT set it is one rank of a
// data-parallel run (train/distributed.h; scripts/launch_distributed.sh).
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <thread>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "train/distributed.h"
#include "train/trainer.h"
#include "usage/hsd_train.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

// Every rank must train the same thing: its resolved config must equal rank
// 0's, except what may differ per host (threads, data.root, loader threads).
void check_same_config(const Config& cfg, bool resume, train::DataParallel& group) {
  Json mine = cfg.resolved;
  mine["--resume"] = resume;  // a rank resuming while another starts afresh would run other collectives
  mine["threads"] = 0;
  if (mine.contains("data")) mine["data"]["root"] = "", mine["data"]["loader_threads"] = 0;
  const Json theirs = Json::parse(group.from_rank0("config", mine.dump()));
  if (theirs == mine) return;
  const Json patch = Json::diff(theirs, mine);
  const Json& first = patch.at(0);
  const std::string path = first.value("path", std::string("/"));
  std::string key = path.substr(1);
  std::replace(key.begin(), key.end(), '/', '.');
  if (key == "--resume")
    input_error("flag --resume", "rank " + std::to_string(group.rank()) + (resume ? " resumes" : " does not resume") +
                                     ", rank 0 " + (resume ? "does not" : "does") + " (all ranks must)");
  const Json::json_pointer ptr(path);
  input_error("config key " + key, "rank " + std::to_string(group.rank()) + " has " +
                                       (mine.contains(ptr) ? mine.at(ptr).dump() : std::string("nothing")) + ", rank 0 has " +
                                       (theirs.contains(ptr) ? theirs.at(ptr).dump() : std::string("nothing")) +
                                       " (all ranks must run the same config)");
}

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  const train::DistributedEnv env = train::DistributedEnv::from_environment();
  if (env.enabled()) train::check_global_batch(cfg, env.world_size);  // before joining: every rank says so itself
  const bool resume = args.has("--resume");
  if (resume && !std::filesystem::exists(args.out_dir + "/checkpoints/last.pt"))
    input_error(args.out_dir + "/checkpoints/last.pt", "no checkpoint to resume from (--resume)");
  if (env.rank == 0) {  // the outputs are checked before any data is made or loaded
    make_dirs(args.out_dir);
    const std::string& o = args.out_dir;
    check_output_paths({o + "/metrics.csv", o + "/config.json", o + "/curves.png", o + "/val_psnr.png",
                        o + "/val_depth.png", o + "/val/x", o + "/checkpoints/last.pt"});
  }
  if (env.rank != 0) log::set_quiet(true);  // rank 0 reports; the others only warn
  // Ranks sharing a host share its cores.
  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  const int threads = setup_threads(cfg.threads > 0 || !env.enabled() ? cfg.threads : std::max(1, cores / env.local_world_size));
  if (env.enabled() && threads * env.local_world_size > cores)
    log::warn(std::to_string(env.local_world_size) + " ranks x " + std::to_string(threads) + " threads on " +
              std::to_string(cores) + " cores: oversubscribed (set threads = 0 to share the cores)");
  std::shared_ptr<train::DataParallel> group;
  if (env.enabled()) {
    group = std::make_shared<train::DataParallel>(env, cfg.distributed);
    log::info("joined: " + group->describe() + ", " + std::to_string(threads) + " threads per rank");
    check_same_config(cfg, resume, *group);
  }
  train::Trainer trainer(cfg, group);
  if (resume) trainer.check_resume(args.out_dir);  // before the data: a bad checkpoint or metrics.csv is found first
  else if (!cfg.train.init_checkpoint.empty()) trainer.start_from(cfg.train.init_checkpoint);
  trainer.attach_data();
  if (trainer.writes_outputs()) {
    make_dirs(args.out_dir);
    write_resolved_config(cfg, args.out_dir);
  }
  const auto t0 = std::chrono::steady_clock::now();
  trainer.run(args.out_dir, resume);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (group)
    log::info("collectives: " + std::to_string(group->collectives()) + " in " + c10::str(group->seconds_communicating()) +
              " s waiting (" + c10::str(100.0 * group->seconds_communicating() / std::max(secs, 1e-9)) + " % of the run)");
  log::info("done in " + c10::str(secs) + " s: curves " + args.out_dir + "/curves.png, metrics " + args.out_dir +
            "/metrics.csv, reconstructions and PSF atlases " + args.out_dir + "/val/, checkpoint " + args.out_dir +
            "/checkpoints/last.pt");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_train", kUsage, {}, {"--resume"}, true, true};
  spec.heap_for_large_blocks = true;  // common/app.h, keep_freed_memory
  return run_app(spec, argc, argv, run);
}
