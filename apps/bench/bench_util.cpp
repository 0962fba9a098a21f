#include "bench/bench_util.h"

#include <algorithm>
#include <chrono>
#include <malloc.h>
#include <fstream>
#include <string>

#include <torch/torch.h>

#include "model/spectral_wiener.h"
#include "optics/sensor.h"

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

void give_batch_spectral_prior(train::Trainer& t, const train::Batch& b) {
  if (!t.net()->options().residual_spectral_wiener) return;
  const int64_t L = b.radiance.size(1);
  const torch::Tensor x = b.radiance.to(torch::kFloat64).transpose(0, 1).reshape({L, -1});  // [L, pixels]
  const torch::Tensor mean = x.mean(1);
  const torch::Tensor centred = x - mean.unsqueeze(1);
  const torch::Tensor cov = torch::matmul(centred, centred.t()) / double(std::max<int64_t>(1, x.size(1) - 1));
  const optics::SensorModel& s = t.sensor();
  const torch::Tensor omega = s.omega.cpu().to(torch::kFloat64);
  const double y_mean = torch::matmul(omega, mean).mean().item<double>();
  const double noise_var = model::mean_noise_variance(s.noise.std_min, s.noise.std_max, s.noise.photons_at_saturation, y_mean);
  t.net()->set_spectral_prior(mean.to(torch::kFloat32), cov.to(torch::kFloat32), noise_var, s.omega.to(torch::kFloat32));
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
