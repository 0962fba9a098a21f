// hsd_bench NAME [--json] [--config FILE] [--set k=v] [--threads N] ...
// Performance figures, measured side by side in one run, with the thread count.
// With --json, stdout holds exactly one JSON object (logs go to stderr).
#include <cstdio>
#include <filesystem>
#include <algorithm>
#include <vector>

#include <torch/torch.h>

#include "bench/benches.h"
#include "common/app.h"
#include "common/build_info.h"
#include "common/error.h"
#include "common/log.h"
#include "usage/hsd_bench.h"

using namespace hsd;

namespace {
const char* kUsage = usage::kText;

int run(const AppArgs& args) {
  if (args.positional.size() != 1) input_error("hsd_bench", "expected one benchmark NAME (see --help)");
  const std::string name = args.positional[0];
  static const std::vector<std::string> kNames{"psf", "sim", "data", "train", "dist", "reconstruct", "accuracy", "apps"};
  if (std::find(kNames.begin(), kNames.end(), name) == kNames.end()) {
    std::string known;
    for (const auto& n : kNames) known += (known.empty() ? "" : ", ") + n;
    input_error("hsd_bench " + name, "unknown benchmark (known: " + known + ")");
  }
  const bool json = args.has("--json");
  if (json) log::set_quiet(true);
  const std::string config = args.config_path.empty() ? std::string(HSD_SOURCE_DIR) + "/configs/paper.json" : args.config_path;
  std::vector<std::string> overrides = args.overrides;
  Config cfg = load_config(config, overrides);
  // Every flag is read before the first progress line, so a bad one is the only
  // line: all of hsd_bench's valued flags but the child's two are integers.
  for (const auto& [flag, value] : args.options)
    if (flag != "--child-mode" && flag != "--child-result") (void)args.integer(flag, 0);
  const int threads = int(args.integer("--threads", cfg.threads));
  // A config that starts from the Fisher design (paper.json) before hsd_fisher
  // has written it: the Fresnel start instead (the timings do not depend on the
  // height values; hsd_bench accuracy's numbers are for that start).
  if (cfg.optics.doe.init == DoeFamily::fisher && !std::filesystem::exists(cfg.optics.doe.fisher_path)) {
    log::info("hsd_bench: no Fisher design at " + cfg.optics.doe.fisher_path + ": benchmarking with the Fresnel start");
    overrides.push_back("optics.doe.init=\"fresnel\"");
    cfg = load_config(config, overrides);
  }
  setup_threads(threads, !json);
  bench::BenchOutput out;
  int rc = 0;
  if (name == "psf") rc = bench::bench_psf(cfg, args, out);
  else if (name == "sim") rc = bench::bench_sim(cfg, args, out);
  else if (name == "data") rc = bench::bench_data(cfg, args, out);
  else if (name == "train") {
    keep_freed_memory(1024, true);  // as hsd_train runs (common/app.h)
    rc = bench::bench_train(cfg, args, out);
  }
  else if (name == "dist") rc = bench::bench_dist(cfg, args, out);
  else if (name == "reconstruct") rc = bench::bench_reconstruct(cfg, args, out);
  else if (name == "accuracy") rc = bench::bench_accuracy(cfg, args, out);
  else if (name == "apps") rc = bench::bench_apps(cfg, config, overrides, args, out);
  out.json["hsd_version"] = HSD_VERSION;
  out.json["config"] = config;
  if (json) std::printf("%s\n", out.json.dump().c_str());
  else std::printf("%s", out.text.c_str());
  return rc;
}
}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_bench", kUsage, {"--threads", "--repeats", "--patch", "--bands", "--depths", "--psf", "--pupil", "--scenes", "--patches", "--batch", "--size", "--tile", "--overlap", "--band-stride", "--ref-oversampling", "--ref-spectral", "--ranks", "--child-mode", "--child-result", "--child-rank"}, {"--json", "--no-baseline", "--profile"}, false, false, 1};
  return run_app(spec, argc, argv, run);
}
