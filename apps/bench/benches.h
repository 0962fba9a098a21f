// The benchmarks of hsd_bench, one function each.
#pragma once
#include <string>
#include <vector>

#include "common/app.h"
#include "common/config.h"

namespace hsd::bench {

struct BenchOutput {
  Json json;         // printed (exactly one object) with --json
  std::string text;  // printed otherwise
};

int bench_psf(const Config& cfg, const AppArgs& args, BenchOutput& out);
int bench_sim(Config cfg, const AppArgs& args, BenchOutput& out);
int bench_data(Config cfg, const AppArgs& args, BenchOutput& out);
int bench_train(Config cfg, const AppArgs& args, BenchOutput& out);
int bench_dist(Config cfg, const AppArgs& args, BenchOutput& out);
int bench_reconstruct(Config cfg, const AppArgs& args, BenchOutput& out);
int bench_accuracy(Config cfg, const AppArgs& args, BenchOutput& out);
// config_path and overrides: what the apps it runs are given.
int bench_apps(Config cfg, const std::string& config_path, const std::vector<std::string>& overrides, const AppArgs& args,
               BenchOutput& out);

}  // namespace hsd::bench
