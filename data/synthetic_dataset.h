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
// `cache`: written by ensure_dataset for training (recorded in generator.json,
// so a later run with other settings may replace it), not by hsd_scenes.
Manifest generate_dataset(const Config& cfg, const std::string& dir, bool cache = false);

// data.root if it holds a manifest; otherwise generates it there when
// data.generate_if_missing, else InputError naming data.root. When the
// folder's generator.json (bands and data.generator; not the seed, so runs
// with other seeds share a dataset) differs from the config: a folder training
// generated itself is generated again, with a warning; anything else (written
// by hsd_scenes, by an earlier hsd without generator.json, or unreadable) is
// used as it is, with a warning: it is the user's. Datasets not made by the
// generator (hsd_import, your own) are used as they are.
std::string ensure_dataset(const Config& cfg);

}  // namespace hsd::data
