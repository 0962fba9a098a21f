#include "data/dataset.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>

#include <torch/torch.h>

#include "common/error.h"
#include "data/band_resample.h"

namespace hsd::data {

std::vector<LoadedScene> load_split(const std::string& root, const std::string& split,
                                    const std::vector<double>& centres_m, double band_width_m, int64_t threads) {
  const Manifest m = read_manifest(root);
  const std::vector<ManifestEntry> entries = split == "all" ? m.scenes : m.split(split);
  if (entries.empty()) input_error(root + "/manifest.json", "has no scene in split \"" + split + "\"");
  const int64_t n = int64_t(entries.size());
  int64_t T = threads > 0 ? threads : int64_t(std::max(1u, std::thread::hardware_concurrency()));
  T = std::min(T, n);
  std::vector<LoadedScene> out(static_cast<size_t>(n));
  std::vector<std::exception_ptr> errors(static_cast<size_t>(n));
  std::atomic<int64_t> next{0};
  auto work = [&] {
    // Each scene is one task (file reading dominates; a scene's tensor ops may
    // use their own intra-op threads).
    for (int64_t i = next++; i < n; i = next++) {
      const auto& e = entries[size_t(i)];
      try {
        const std::string path = root + "/" + e.file;
        out[size_t(i)] = {e.file, e.split, e.notes, resample_scene_bands(read_scene_exr(path), centres_m, band_width_m, path)};
      } catch (...) {
        errors[size_t(i)] = std::current_exception();
      }
    }
  };
  std::vector<std::thread> pool;
  try {
    for (int64_t t = 1; t < T; ++t) pool.emplace_back(work);
  } catch (...) {  // could not start a thread: the ones running finish the work
  }
  work();
  for (auto& th : pool) th.join();
  for (auto& err : errors)  // the first failing scene in manifest order, whatever the timing
    if (err) std::rethrow_exception(err);
  return out;
}

}  // namespace hsd::data
