// hsd_bench apps: the apps as a user runs them, whole processes (start-up,
// library load, inputs, work, outputs): `hsd_psf --help`, and hsd_simulate on
// the same --size² scene occupying one depth layer and all of the config's
// layers, side by side, medians of --repeats runs each, interleaved. What the
// simulator leaves out for the one-layer scene must show in the whole process.
#include <unistd.h>

#include <cstdio>
#include <filesystem>

#include <torch/torch.h>

#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/subprocess.h"
#include "data/scene_exr.h"

namespace hsd::bench {

namespace {

namespace fs = std::filesystem;

// Runs argv (stdout and stderr dropped) and returns the wall seconds; throws when it fails.
double run_seconds(const std::vector<std::string>& args) {
  ProcessEnd end;
  const double s = seconds([&] { end = run_process(args, /*quiet=*/true); });
  if (!end.ok()) {
    std::string shown;
    for (const auto& x : args) shown += " " + x;
    throw std::runtime_error("hsd_bench apps: a run failed (" + end.describe() + "):" + shown);
  }
  return s;
}

// A reflectance scene of size² px in the config's bands: smooth random
// spectra, depth either one layer (the middle one) or vertical stripes over all.
data::SpectralScene scene(const Config& cfg, int64_t size, bool one_layer) {
  torch::manual_seed(int64_t(cfg.seed));
  data::SpectralScene s;
  s.wavelengths_m = cfg.optics.wavelengths_m();
  const int64_t L = int64_t(s.wavelengths_m.size());
  s.spectral = torch::nn::functional::interpolate(
                   torch::rand({1, L, size / 16, size / 16}),
                   torch::nn::functional::InterpolateFuncOptions().size(std::vector<int64_t>{size, size}).mode(torch::kBilinear).align_corners(false))[0]
                   .clamp(0.02, 0.98);
  const auto& d = cfg.optics.depths_m;
  const int64_t Z = int64_t(d.size());
  s.depth_m = torch::empty({1, size, size});
  if (one_layer) {
    s.depth_m.fill_(d[size_t(Z / 2)]);
  } else {
    for (int64_t z = 0; z < Z; ++z) s.depth_m.narrow(2, z * size / Z, (z + 1) * size / Z - z * size / Z).fill_(d[size_t(z)]);
  }
  s.mask = torch::ones({1, size, size});
  return s;
}

}  // namespace

int bench_apps(Config cfg, const std::string& config_path, const std::vector<std::string>& overrides, const AppArgs& args,
               BenchOutput& out) {
  const int64_t size = args.integer("--size", 384);
  const int repeats = int(args.integer("--repeats", 3));
  if (size < 32 || size > 4096) input_error("--size", "must be in [32, 4096]");
  if (repeats < 1 || repeats > 100) input_error("--repeats", "must be in [1, 100]");
  const fs::path bin = fs::canonical("/proc/self/exe").parent_path().parent_path() / "bin";
  const fs::path tmp = fs::temp_directory_path() / ("hsd_bench_apps_" + std::to_string(::getpid()));
  make_dirs(tmp.string());
  const std::string one = (tmp / "one_layer.exr").string(), all = (tmp / "all_layers.exr").string();
  data::write_scene_exr(one, scene(cfg, size, true));
  data::write_scene_exr(all, scene(cfg, size, false));
  auto simulate = [&](const std::string& scene_file) {
    std::vector<std::string> a{(bin / "hsd_simulate").string(), "--config", config_path, "--scene", scene_file,
                               "--out", (tmp / "out").string()};
    for (const auto& o : overrides) a.push_back("--set"), a.push_back(o);
    a.push_back("--set"), a.push_back("threads=" + std::to_string(torch::get_num_threads()));
    return a;
  };
  std::vector<double> t_help, t_start, t_one, t_all;
  log::info("whole processes: hsd_psf --help, hsd_simulate on one layer and on " +
            std::to_string(cfg.optics.depths_m.size()) + " (" + std::to_string(repeats) + " runs each, interleaved) ...");
  run_seconds(simulate(one));  // warm-up: the page cache holds the libraries
  for (int i = 0; i < repeats; ++i) {
    t_help.push_back(run_seconds({(bin / "hsd_psf").string(), "--help"}));
    // Two flags pass the launcher: the app itself starts (LibTorch loaded), prints its usage and exits.
    t_start.push_back(run_seconds({(bin / "hsd_simulate").string(), "--help", "-h"}));
    t_one.push_back(run_seconds(simulate(one)));
    t_all.push_back(run_seconds(simulate(all)));
  }
  fs::remove_all(tmp);
  const double help = median(t_help), start = median(t_start), s1 = median(t_one), sZ = median(t_all);
  const int64_t Z = int64_t(cfg.optics.depths_m.size());
  out.json = Json{{"bench", "apps"},          {"threads", torch::get_num_threads()}, {"size", size},
                  {"layers", Z},              {"bands", int64_t(cfg.optics.wavelengths_nm.size())},
                  {"seconds_psf_help", help}, {"seconds_app_start", start}, {"seconds_simulate_one_layer", s1},
                  {"seconds_simulate_all_layers", sZ}, {"ratio_one_to_all", s1 / sZ},
                  {"ratio_one_to_all_after_start", (s1 - start) / (sZ - start)}};
  char buf[768];
  std::snprintf(buf, sizeof buf,
                "whole processes (median of %d), threads %d:\n"
                "  hsd_psf --help                                %7.3f s\n"
                "  hsd_simulate --help -h (the app's start-up)   %7.3f s\n"
                "  hsd_simulate, %lldx%lld scene, 1 depth layer      %7.3f s\n"
                "  hsd_simulate, %lldx%lld scene, %lld depth layers     %7.3f s\n"
                "  one layer / all layers                         %6.2fx\n"
                "  the same after the start-up                    %6.2fx\n",
                repeats, torch::get_num_threads(), help, start, (long long)size, (long long)size, s1, (long long)size, (long long)size,
                (long long)Z, sZ, s1 / sZ, (s1 - start) / (sZ - start));
  out.text = buf;
  return 0;
}

}  // namespace hsd::bench
