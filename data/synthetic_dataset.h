// A whole synthetic dataset on disk (what hsd_scenes writes, and what training
// generates on first use when data.root holds no manifest): the
// data.generator.{train,val,test}_scenes tabletop scenes and the ColorChecker
// scene (test split), each with sRGB (D65) and depth previews, plus
// manifest.json and colorchecker_layout.json. Scene i of a split has its own
// seed derived from the config's seed, so changing a count keeps the others.
#pragma once
#include <string>

#include "common/config.h"
#include "data/manifest.h"

namespace hsd::data {

// Writes into `dir` (created); returns the manifest written. Progress on stderr.
Manifest generate_dataset(const Config& cfg, const std::string& dir);

// data.root if it holds a manifest; otherwise generates it there when
// data.generate_if_missing, else InputError naming data.root.
std::string ensure_dataset(const Config& cfg);

}  // namespace hsd::data
