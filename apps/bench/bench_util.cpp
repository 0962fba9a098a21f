#include "bench/bench_util.h"

#include <algorithm>
#include <chrono>
#include <malloc.h>
#include <fstream>
#include <string>

#include <torch/torch.h>

#include "train/baselines.h"

namespace hsd::bench {

train::Batch striped_batch(const Config& cfg, int64_t batch, int64_t patch) {
  const int64_t L = int64_t(cfg.optics.wavelengths_nm.size()), Z = int64_t(cfg.optics.depths_m.size());
  torch::manual_seed(int64_t(cfg.seed));
  train::Batch b;
  b.radiance = torch::rand({batch, L, patch, patch});
  b.depth_m = torch::empty({batch, 1, patch, patch});
  for (int64_t z = 0; z < Z; ++z)
    b.depth_m.narrow(3, z * patch / Z, (z + 1) * patch / Z - z * patch / Z).fill_(cfg.optics.depths_m[size_t(z)]);
  return b;
}

void give_batch_spectral_prior(train::Trainer& t, const Config& cfg, const train::Batch& b) {
  if (!t.net()->options().residual_spectral_wiener) return;
  std::vector<data::LoadedScene> scenes(size_t(b.radiance.size(0)));  // the batch as radiance scenes
  for (size_t i = 0; i < scenes.size(); ++i) {
    data::SpectralScene& sc = scenes[i].scene;
    sc.kind = data::SpectralKind::Radiance;
    sc.spectral = b.radiance[int64_t(i)];
    sc.depth_m = b.depth_m[int64_t(i)];
    sc.mask = torch::ones_like(sc.depth_m);
  }
  const model::SpectralPrior p = train::training_spectral_prior(scenes, cfg, t.sensor());
  t.net()->set_spectral_prior(p.mean, p.covariance, p.noise_var, t.sensor().omega.to(torch::kFloat32));
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

double seconds(const std::function<void()>& f) {
  const auto a = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count();
}

double median_seconds(const std::function<void()>& f, int repeats, bool warmup) {
  if (warmup) f();
  std::vector<double> t;
  for (int i = 0; i < std::max(1, repeats); ++i) t.push_back(seconds(f));
  return median(std::move(t));
}

namespace {
double status_mib(const std::string& key) {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind(key, 0) == 0) return std::stod(line.substr(key.size())) / 1024.0;  // kB -> MiB
  return 0.0;
}
}  // namespace

void reset_peak_rss() {
  malloc_trim(0);  // hand freed heap pages back, so the peak counts this run only
  std::ofstream("/proc/self/clear_refs") << "5";
}
double peak_rss_mib() { return status_mib("VmHWM:"); }
double current_rss_mib() { return status_mib("VmRSS:"); }

double peak_rss_during(const std::function<void()>& f) {
  reset_peak_rss();
  f();
  return peak_rss_mib();
}

}  // namespace hsd::bench
