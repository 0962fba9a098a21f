// Loading a dataset folder (manifest.json + scene EXRs) for one split: scenes
// read in parallel (data.loader_threads), each resampled to the config's bands
// when its own differ, returned in manifest order whatever the thread timing.
#pragma once
#include <string>
#include <vector>

#include "data/manifest.h"
#include "data/scene_exr.h"

namespace hsd::data {

struct LoadedScene {
  std::string file;   // as in the manifest
  std::string split;
  std::string notes;
  SpectralScene scene;  // on the config's bands
};

// Scenes of `split` ("train", "val", "test" or "all"), in manifest order.
// InputError (naming the file) for a bad scene, or when the split is empty.
std::vector<LoadedScene> load_split(const std::string& root, const std::string& split,
                                    const std::vector<double>& centres_m, double band_width_m, int64_t threads);

}  // namespace hsd::data
