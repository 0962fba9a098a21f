// A whole synthetic dataset on disk (what hsd_scenes writes, and what training
// generates on first use when data.root holds no manifest): the
// data.generator.{train,val,test}_scenes scenes in the configured layouts and
// the ColorChecker scene (test split), each with sRGB (D65) and depth
// previews, plus manifest.json, colorchecker_layout.json, generator.json (what
// generated it) and realism.json/.md (data/realism_stats.h). Scene i of a split
// has its own seed derived from the config's seed, so changing a count keeps
// the others.
#pragma once
#include <string>

#include "common/config.h"
#include "data/manifest.h"

namespace hsd::data {

// Writes into `dir` (created); returns the manifest written. Progress on stderr.
Manifest generate_dataset(const Config& cfg, const std::string& dir);

// data.root if it holds a manifest; otherwise generates it there when
// data.generate_if_missing, else InputError naming data.root. A folder the
// generator wrote (generator.json records seed, bands and data.generator) is
// generated again, with a warning, when the config asks for other scenes;
// folders written by anything else are used as they are.
std::string ensure_dataset(const Config& cfg);

}  // namespace hsd::data
