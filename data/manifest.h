// A dataset is a folder of scene EXRs plus manifest.json (docs/formats.md):
//   { "format": "hsd-dataset", "version": 1,
//     "wavelengths_nm": [...], "band_width_nm": 10,      (what the scenes hold; informative)
//     "scenes": [ { "file": "scene_train_000.exr", "split": "train", "notes": "..." }, ... ] }
// Splits are "train", "val" and "test"; files are relative to the folder.
#pragma once
#include <string>
#include <vector>

namespace hsd::data {

struct ManifestEntry {
  std::string file;   // relative to the dataset folder
  std::string split;  // train | val | test
  std::string notes;
};

struct Manifest {
  std::vector<double> wavelengths_nm;
  double band_width_nm = 0.0;
  std::vector<ManifestEntry> scenes;

  std::vector<ManifestEntry> split(const std::string& name) const;
};

// Reads DIR/manifest.json. InputError naming the file and the entry for a
// missing file, an unknown split, a duplicate or a malformed document.
Manifest read_manifest(const std::string& dir);
// Writes DIR/manifest.json atomically.
void write_manifest(const std::string& dir, const Manifest& m);
bool has_manifest(const std::string& dir);

}  // namespace hsd::data
