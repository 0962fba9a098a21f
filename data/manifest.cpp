#include "data/manifest.h"

#include <filesystem>
#include <set>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/json_reader.h"

namespace hsd::data {

std::vector<ManifestEntry> Manifest::split(const std::string& name) const {
  std::vector<ManifestEntry> out;
  for (const auto& e : scenes)
    if (e.split == name) out.push_back(e);
  return out;
}

bool has_manifest(const std::string& dir) { return std::filesystem::exists(dir + "/manifest.json"); }

Manifest read_manifest(const std::string& dir) {
  const std::string path = dir + "/manifest.json";
  if (!std::filesystem::exists(path)) input_error(path, "no manifest.json in the dataset folder (make one with hsd_scenes)");
  const Json j = read_json_file(path);
  if (!j.is_object() || !j.contains("scenes") || !j["scenes"].is_array())
    input_error(path, "expected an object with a \"scenes\" array");
  Manifest m;
  if (j.contains("wavelengths_nm") && j["wavelengths_nm"].is_array())
    for (const auto& w : j["wavelengths_nm"])
      if (w.is_number()) m.wavelengths_nm.push_back(w.get<double>());
  if (j.contains("band_width_nm") && j["band_width_nm"].is_number()) m.band_width_nm = j["band_width_nm"].get<double>();
  std::set<std::string> seen;
  for (size_t i = 0; i < j["scenes"].size(); ++i) {
    const Json& s = j["scenes"][i];
    const std::string where = "scenes[" + std::to_string(i) + "]";
    if (!s.is_object() || !s.contains("file") || !s["file"].is_string() || !s.contains("split") || !s["split"].is_string())
      input_error(path, where + " needs string keys \"file\" and \"split\"");
    ManifestEntry e{s["file"].get<std::string>(), s["split"].get<std::string>(),
                    s.contains("notes") && s["notes"].is_string() ? s["notes"].get<std::string>() : ""};
    if (e.split != "train" && e.split != "val" && e.split != "test")
      input_error(path, where + ".split is \"" + e.split + "\", expected train, val or test");
    if (e.file.empty() || e.file.find("..") != std::string::npos || e.file[0] == '/')
      input_error(path, where + ".file must be a relative path inside the folder, got \"" + e.file + "\"");
    if (!seen.insert(e.file).second) input_error(path, where + " lists " + e.file + " twice");
    if (!std::filesystem::exists(dir + "/" + e.file)) input_error(path, where + " names a missing file " + e.file);
    m.scenes.push_back(e);
  }
  if (m.scenes.empty()) input_error(path, "lists no scenes");
  return m;
}

void write_manifest(const std::string& dir, const Manifest& m) {
  Json scenes = Json::array();
  for (const auto& e : m.scenes) scenes.push_back(Json{{"file", e.file}, {"split", e.split}, {"notes", e.notes}});
  Json j{{"format", "hsd-dataset"}, {"version", 1}, {"wavelengths_nm", m.wavelengths_nm},
         {"band_width_nm", m.band_width_nm}, {"scenes", scenes}};
  write_text_file(dir + "/manifest.json", j.dump(2) + "\n");
}

}  // namespace hsd::data
