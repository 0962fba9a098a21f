#include "bench/bench_util.h"

#include <algorithm>
#include <chrono>
#include <malloc.h>
#include <fstream>
#include <string>

namespace hsd::bench {

double median_seconds(const std::function<void()>& f, int repeats, bool warmup) {
  if (warmup) f();
  std::vector<double> t;
  for (int i = 0; i < std::max(1, repeats); ++i) {
    const auto a = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
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
