#include "data/synthetic_dataset.h"

#include <array>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>

#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/image_io.h"
#include "data/preview.h"
#include "data/reflectance_library.h"
#include "data/measured_reflectances.h"
#include "data/real_test_set.h"
#include "data/realism_stats.h"
#include "data/depth_structure.h"
#include "data/scene_generator.h"
#include "data/texture_bank.h"
#include "data/textured_scene.h"
#include "optics/spectrum.h"

namespace hsd::data {

namespace {
// Seed of scene i of a split: distinct streams per split, stable when counts change.
uint64_t scene_seed(uint64_t seed, int split, int64_t i) {
  uint64_t x = seed * 0x9E3779B97F4A7C15ull + uint64_t(split) * 0xBF58476D1CE4E5B9ull + uint64_t(i) * 0x94D049BB133111EBull;
  x ^= x >> 31;
  return x * 0xD6E8FEB86659FD93ull;
}

// What a generated dataset was generated from: bands and data.generator.
// The seed is left out: runs with other seeds (hsd_ablate --seeds) share one
// dataset, as they always did, so their spread is the training's, not the data's.
Json generator_record(const Config& cfg) {
  return Json{{"wavelengths_nm", cfg.optics.wavelengths_nm},
              {"band_width_nm", cfg.optics.band_width_m() * 1e9},
              {"generator", cfg.resolved.contains("data") && cfg.resolved["data"].contains("generator")
                                ? cfg.resolved["data"]["generator"]
                                : Json::object()}};
}

// realism.json and realism.md: the generated scenes' statistics against the
// CAVE cube's, and their depth structure per layout against real depth maps
// at the same size and range (depth_structure.h); a summary in the log.
void write_realism_report(const std::string& dir, const GeneratorConfig& g, const RealismSpec& rspec,
                          std::vector<SceneRealism> realism,
                          const std::map<std::string, std::vector<double>>& structure_by_layout) {
  const RealismSummary sum = summarise_realism(std::move(realism));
  const SceneRealism ref = cave_realism(rspec);
  Json rj = realism_json(sum, &ref);
  std::string md = realism_markdown(sum, &ref);
  md += "\nDepth structure (the resolution oracle's depth RMSE at a " +
        std::to_string(structure_window_px(g.height_px, g.width_px)) +
        "-px box over that of the map's median depth; 0 = smooth at that scale, 1 = no better than a constant): "
        "real depth maps at this size and depth range against the generated layouts.\n\n| depth map | depth structure |\n|---|---|\n";
  Json refs = Json::array();
  double real_sum = 0, real_lo = 1e9, real_hi = -1e9;
  const auto maps = reference_depth_maps(g.height_px, g.width_px, g.depth_min_m, g.depth_max_m);
  for (const auto& r : maps) {
    const double v = depth_structure(r.depth_m, r.mask);
    real_sum += v, real_lo = std::min(real_lo, v), real_hi = std::max(real_hi, v);
    refs.push_back(Json{{"name", r.name}, {"depth_structure", v}});
    char b[160];
    std::snprintf(b, sizeof b, "| %s (real) | %.2f |\n", r.name.c_str(), v);
    md += b;
  }
  std::string layouts_line;
  for (const auto& [layout, v] : structure_by_layout) {
    double s = 0, n = 0;
    for (double x : v)
      if (std::isfinite(x)) s += x, n += 1;
    if (n == 0) continue;
    char b[160];
    std::snprintf(b, sizeof b, "| %s (generated, mean of %d) | %.2f |\n", layout.c_str(), int(n), s / n);
    md += b;
    std::snprintf(b, sizeof b, "%s%s %.2f", layouts_line.empty() ? "" : ", ", layout.c_str(), s / n);
    layouts_line += b;
    rj["depth_structure_by_layout"][layout] = s / n;
  }
  rj["depth_structure_references"] = refs;
  write_text_file(dir + "/realism.json", rj.dump(2) + "\n");
  write_text_file(dir + "/realism.md", md);
  log::info("realism of the generated scenes (" + dir + "/realism.md; reference: the CAVE balloons cube):\n" + md);
  for (const auto& line : check_realism(sum.mean)) log::info("realism: " + line);
  char b[300];
  std::snprintf(b, sizeof b, "realism: depth structure %s against real depth maps %.2f .. %.2f (mean %.2f)",
                layouts_line.c_str(), real_lo, real_hi, real_sum / double(maps.size()));
  log::info(b);
}

// colorchecker_layout.json: where each patch of the test chart is.
void write_colorchecker_layout(const std::string& path, const std::vector<std::array<int64_t, 4>>& boxes,
                               const std::vector<std::string>& names, double depth_m) {
  Json patches = Json::array();
  for (size_t i = 0; i < boxes.size(); ++i)
    patches.push_back(Json{{"name", names[i]}, {"box_xyxy", {boxes[i][0], boxes[i][1], boxes[i][2], boxes[i][3]}}});
  write_text_file(path, Json{{"scene", "colorchecker.exr"}, {"illuminant", "D65"}, {"depth_m", depth_m},
                             {"patches", patches}}.dump(2) + "\n");
}

}  // namespace

Manifest generate_dataset(const Config& cfg, const std::string& dir, bool cache) {
  const auto& g = cfg.data.generator;
  const std::vector<double> bands = cfg.optics.wavelengths_m();
  const double bw = cfg.optics.band_width_m();
  const ReflectanceLibrary lib(bands, bw);  // checks the spectral tables before any output
  // The realistic layouts' sources, loaded only when a layout needs them.
  bool textured = false;
  for (const auto& [layout, w] : g.layouts) textured |= (w > 0 && layout != SceneLayout::classic_tabletop);
  std::unique_ptr<MeasuredReflectances> measured;
  std::unique_ptr<TextureBank> textures;
  if (textured) {
    measured = std::make_unique<MeasuredReflectances>(bands, bw, g.spectral_exclusion);
    textures = std::make_unique<TextureBank>(g.texture_dir.empty() ? TextureBank::default_dir() : g.texture_dir);
  }
  const RealismSpec rspec = with_band_weights({bands, bw, cfg.sensor.camera, g.depth_min_m, g.depth_max_m, 8});
  std::vector<SceneRealism> realism;
  std::map<std::string, std::vector<double>> structure_by_layout;  // depth structure per layout
  const torch::Tensor d65 = optics::illuminant_bands("D65", bands, bw);
  const std::array<std::pair<const char*, int64_t>, 3> splits{
      {{"train", g.train_scenes}, {"val", g.val_scenes}, {"test", g.test_scenes}}};
  int64_t total = g.colorchecker ? 1 : 0;
  for (const auto& [name, n] : splits) total += n;
  if (total == 0) input_error("config key data.generator", "asks for no scenes at all");
  make_dirs(dir);
  std::filesystem::remove(dir + "/manifest.json");  // written last: its presence marks a complete dataset

  Manifest m;
  m.wavelengths_nm = cfg.optics.wavelengths_nm;
  m.band_width_nm = bw * 1e9;
  auto write_scene = [&](const std::string& name, const GeneratedScene& s, const std::string& split) {
    write_scene_exr(dir + "/" + name + ".exr", s.scene, g.half);
    write_srgb_png(dir + "/" + name + "_srgb.png", spectral_to_linear_srgb(s.scene.spectral, bands, bw, d65));
    write_depth_png(dir + "/" + name + "_depth.png", s.scene.depth_m, s.scene.mask, g.depth_min_m, g.depth_max_m);
    m.scenes.push_back({name + ".exr", split, s.notes});
  };
  log::Progress progress("scenes", long(total));
  for (int split = 0; split < 3; ++split) {
    const auto& [name, n] = splits[size_t(split)];
    for (int64_t i = 0; i < n; ++i) {
      char stem[64];
      std::snprintf(stem, sizeof stem, "scene_%s_%03lld", name, (long long)i);
      const uint64_t seed = scene_seed(cfg.seed, split, i);
      const SceneLayout layout = pick_layout(g, seed);
      GeneratedScene gs = layout == SceneLayout::classic_tabletop ? generate_tabletop_scene(g, lib, bands, seed)
                        : layout == SceneLayout::tabletop
                            ? generate_textured_tabletop_scene(g, SceneSources{*measured, *textures}, bands, seed)
                            : generate_dead_leaves_scene(g, SceneSources{*measured, *textures}, bands, seed);
      realism.push_back(measure_realism(gs.scene, rspec, stem));
      structure_by_layout[choice_name(layout)].push_back(realism.back().depth_structure);
      write_scene(stem, gs, name);
      progress.step();
    }
  }
  if (g.colorchecker) {
    std::vector<std::array<int64_t, 4>> boxes;
    write_scene("colorchecker", generate_colorchecker_scene(g, lib, bands, &boxes), "test");
    write_colorchecker_layout(dir + "/colorchecker_layout.json", boxes, lib.patch_names(), g.colorchecker_depth_m);
    progress.step();
  }
  progress.finish();
  if (!realism.empty()) write_realism_report(dir, g, rspec, std::move(realism), structure_by_layout);
  Json record = generator_record(cfg);
  record["written_by"] = cache ? "training (data.generate_if_missing)" : "hsd_scenes";
  write_text_file(dir + "/generator.json", record.dump(2) + "\n");
  write_manifest(dir, m);  // last: a folder with a manifest is complete
  return m;
}

std::string ensure_dataset(const Config& cfg) {
  const std::string& root = cfg.data.root;
  if (has_manifest(root)) {
    // Only the generator writes colorchecker_layout.json and generator.json; see
    // the header for what is replaced and what is only warned about.
    const bool ours = std::filesystem::exists(root + "/generator.json") || std::filesystem::exists(root + "/colorchecker_layout.json");
    if (!ours || !cfg.data.generate_if_missing) return root;
    std::string why;
    bool replace = true;
    if (!std::filesystem::exists(root + "/generator.json")) {
      why = "it was generated by an earlier hsd (no generator.json: perhaps the flat-coloured classic scenes; delete "
            "the folder to generate the current layouts)";
      replace = false;
    } else {
      Json old;
      try {
        old = Json::parse(read_text_file(root + "/generator.json"));
      } catch (const std::exception&) {
      }
      if (!old.is_object()) why = "its generator.json is unreadable", replace = false;
      if (why.empty()) {
        const std::string by = old.value("written_by", std::string("hsd_scenes"));
        old.erase("written_by");
        if (old != generator_record(cfg)) {
          why = "it was generated with other seed, bands or data.generator settings";
          replace = by != "hsd_scenes";
        }
      }
    }
    if (why.empty()) return root;
    if (!replace) {
      log::warn("dataset " + root + ": " + why + " (not training's own: yours); using it as it is");
      return root;
    }
    log::warn("dataset " + root + ": " + why + "; generating it again (data.generator)");
    generate_dataset(cfg, root, /*cache=*/true);
    return root;
  }
  if (!cfg.data.generate_if_missing)
    input_error("config key data.root", "\"" + cfg.data.root + "\" has no manifest.json (run hsd_scenes, or set data.generate_if_missing)");
  log::info("no dataset in " + cfg.data.root + ": generating one (data.generator)");
  generate_dataset(cfg, cfg.data.root, /*cache=*/true);
  return cfg.data.root;
}

}  // namespace hsd::data
