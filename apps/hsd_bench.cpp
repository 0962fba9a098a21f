// hsd_bench NAME [--json] [--config FILE] [--set k=v] [--threads N] ...
// Performance figures, measured side by side in one run, with the thread count.
// With --json, stdout holds exactly one JSON object (logs go to stderr).
#include <cstdio>
#include <filesystem>
#include <set>

#include <torch/torch.h>

#include "bench/benches.h"
#include "common/app.h"
#include "common/build_info.h"
#include "common/error.h"
#include "common/log.h"

using namespace hsd;

namespace {
const char* kUsage =
    "hsd_bench NAME [--json] [--config FILE] [--set key=VALUE ...] [--threads N] [--repeats K]\n"
    "  NAME: psf   time, peak memory and accuracy of the config's whole PSF stack\n"
    "              (forward, forward+backward), with the FFT+bilinear baseline\n"
    "              and point-sampled pixels side by side (--no-baseline skips it)\n"
    "  NAME: sim   forward+backward of PSF + sensor image formation on one patch,\n"
    "              with the straightforward baseline and the floor of bare GEMMs/FFTs;\n"
    "              --patch 256 --bands 25 --depths 7 --psf 63 --pupil 512 set the work\n"
    "  NAME: data  the data path: scene generation, loading with 1 and N threads,\n"
    "              the patch sampler and patch extraction (--scenes 8)\n"
    "  NAME: train seconds per training step and peak memory (--patch 256 --batch 1)\n"
    "  NAME: dist  data-parallel training against one process on the same global\n"
    "              batch: --ranks local ranks (Gloo, cores/ranks threads each) with\n"
    "              global and per-rank batch norm, the same work as independent\n"
    "              processes (the machine's floor), the share in collectives, and\n"
    "              the gradient average bucketed vs per tensor\n"
    "              (--ranks 2 --batch 4 --patch 128)\n"
    "  NAME: reconstruct  seconds per megapixel of the exported reconstructor in tiles,\n"
    "              float32 and bfloat16 (--size 2048 --tile 512 --overlap 32)\n"
    "  NAME: accuracy --out DIR  error against run time of the simulator's knobs\n"
    "              (precision, pixel nodes, low-rank cut, pupil oversampling, cell\n"
    "              integration, spectral samples, window, FFT method) against a\n"
    "              converged float64 reference, and what leaving out unneeded work\n"
    "              saves: error_vs_runtime.csv/.png, leave_out.csv, accuracy.md\n"
    "              (--patch 128 --band-stride 3 --ref-oversampling 4 --ref-spectral 5)\n"
    "  --config defaults to configs/paper.json of the source tree.\n"
    "  --json prints exactly one JSON object on stdout.";

int run(const AppArgs& args) {
  if (args.positional.size() != 1) input_error("hsd_bench", "expected one benchmark NAME (see --help)");
  const std::string name = args.positional[0];
  static const std::set<std::string> kNames{"psf", "sim", "data", "train", "dist", "reconstruct", "accuracy"};
  if (!kNames.count(name)) input_error("hsd_bench " + name, "unknown benchmark (known: psf, sim, data, train, dist, reconstruct, accuracy)");
  const bool json = args.has("--json");
  if (json) log::set_quiet(true);
  const std::string config = args.config_path.empty() ? std::string(HSD_SOURCE_DIR) + "/configs/paper.json" : args.config_path;
  Config cfg = load_config(config, args.overrides);
  // Every flag is read before the first progress line, so a bad one is the only
  // line: all of hsd_bench's valued flags but the child's two are integers.
  for (const auto& [flag, value] : args.options)
    if (flag != "--child-mode" && flag != "--child-result") (void)args.integer(flag, 0);
  const int threads = int(args.integer("--threads", cfg.threads));
  // A config that starts from the Fisher design (paper.json) before hsd_fisher
  // has written it: the Fresnel start instead (the timings do not depend on the
  // height values; hsd_bench accuracy's numbers are for that start).
  if (cfg.optics.doe.init == "fisher" && !std::filesystem::exists(cfg.optics.doe.fisher_path)) {
    log::info("hsd_bench: no Fisher design at " + cfg.optics.doe.fisher_path + ": benchmarking with the Fresnel start");
    std::vector<std::string> o = args.overrides;
    o.push_back("optics.doe.init=\"fresnel\"");
    cfg = load_config(config, o);
  }
  setup_threads(threads, !json);
  bench::BenchOutput out;
  int rc = 0;
  if (name == "psf") rc = bench::bench_psf(cfg, args, out);
  else if (name == "sim") rc = bench::bench_sim(cfg, args, out);
  else if (name == "data") rc = bench::bench_data(cfg, args, out);
  else if (name == "train") rc = bench::bench_train(cfg, args, out);
  else if (name == "dist") rc = bench::bench_dist(cfg, args, out);
  else if (name == "reconstruct") rc = bench::bench_reconstruct(cfg, args, out);
  else if (name == "accuracy") rc = bench::bench_accuracy(cfg, args, out);
  else input_error("hsd_bench " + name, "unknown benchmark (known: psf, sim, data, train, dist, reconstruct, accuracy)");
  out.json["hsd_version"] = HSD_VERSION;
  out.json["config"] = config;
  if (json) std::printf("%s\n", out.json.dump().c_str());
  else std::printf("%s", out.text.c_str());
  return rc;
}
}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_bench", kUsage, {"--threads", "--repeats", "--patch", "--bands", "--depths", "--psf", "--pupil", "--scenes", "--batch", "--size", "--tile", "--overlap", "--band-stride", "--ref-oversampling", "--ref-spectral", "--ranks", "--child-mode", "--child-result", "--child-rank"}, {"--json", "--no-baseline"}, false, false, 1};
  return run_app(spec, argc, argv, run);
}
