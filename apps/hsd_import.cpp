// hsd_import: a real RGB-D picture (an sRGB photograph and its disparity map)
// as a spectral scene (data/rgbd_import.h): DIR/<name>.exr, its previews, and
// an entry in DIR/manifest.json (test split; created or updated).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/image_io.h"
#include "data/manifest.h"
#include "data/preview.h"
#include "data/reflectance_library.h"
#include "data/rgbd_import.h"
#include "optics/spectrum.h"
#include "usage/hsd_import.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  data::RgbdImport in;
  in.rgb_path = args.option("--rgb", "");
  in.disparity_path = args.option("--disparity", "");
  if (in.rgb_path.empty()) input_error("--rgb", "required (an sRGB image)");
  if (in.disparity_path.empty()) input_error("--disparity", "required (a disparity PNG, 0 = unknown)");
  in.near_m = args.number("--near-m", cfg.data.generator.depth_min_m);
  in.far_m = args.number("--far-m", cfg.data.generator.depth_max_m);
  in.focal_px = args.number("--focal-px", 0.0);
  in.baseline_m = args.number("--baseline-m", 0.0);
  in.doffs_px = args.number("--doffs-px", 0.0);
  in.scale = args.number("--scale", 1.0);
  // Calibrated mapping: all three flags or none (a 0 is not "unset").
  const bool calibrated = args.has("--focal-px") || args.has("--baseline-m") || args.has("--doffs-px");
  if (calibrated) {
    if (!args.has("--focal-px") || !args.has("--baseline-m"))
      input_error(args.has("--focal-px") ? "--baseline-m" : "--focal-px", "required with the calibrated mapping (--focal-px F --baseline-m B [--doffs-px D])");
    if (!(in.focal_px > 0.0)) input_error("--focal-px", "must be > 0, got " + args.option("--focal-px", ""));
    if (!(in.baseline_m > 0.0)) input_error("--baseline-m", "must be > 0, got " + args.option("--baseline-m", ""));
    if (args.has("--near-m") || args.has("--far-m"))
      input_error("--near-m/--far-m", "not used with the calibrated mapping (--focal-px); give one or the other");
  }
  const std::string name = args.option("--name", std::filesystem::path(in.rgb_path).stem().string());
  if (name.empty() || name.find('/') != std::string::npos || name.find("..") != std::string::npos)
    input_error("--name", "must be a plain file stem (no '/', no '..')");
  const std::vector<double> bands = cfg.optics.wavelengths_m();
  const double bw = cfg.optics.band_width_m();
  const data::ReflectanceLibrary lib(bands, bw);
  std::string notes;
  const data::SpectralScene s = data::import_rgbd(in, lib, bands, bw, &notes);
  data::Manifest m;
  if (data::has_manifest(args.out_dir)) m = data::read_manifest(args.out_dir);  // checked before writing anything
  for (const auto& e : m.scenes)
    if (e.file == name + ".exr" && e.split != "test")
      input_error("--name", "\"" + name + "\" is already a " + e.split + " scene in " + args.out_dir + "/manifest.json");
  setup_threads(cfg.threads);
  make_dirs(args.out_dir);
  data::write_scene_exr(args.out_dir + "/" + name + ".exr", s, cfg.data.generator.half);
  const torch::Tensor d65 = optics::illuminant_bands("D65", bands, bw);
  data::write_srgb_png(args.out_dir + "/" + name + "_srgb.png", data::spectral_to_linear_srgb(s.spectral, bands, bw, d65));
  const double z_lo = s.depth_m.masked_select(s.mask > 0.5).min().item<double>();
  const double z_hi = s.depth_m.masked_select(s.mask > 0.5).max().item<double>();
  data::write_depth_png(args.out_dir + "/" + name + "_depth.png", s.depth_m, s.mask, z_lo, z_hi);
  if (m.wavelengths_nm.empty()) {
    m.wavelengths_nm = cfg.optics.wavelengths_nm;
    m.band_width_nm = bw * 1e9;
  }
  m.scenes.erase(std::remove_if(m.scenes.begin(), m.scenes.end(),
                                [&](const data::ManifestEntry& e) { return e.file == name + ".exr"; }),
                 m.scenes.end());
  m.scenes.push_back({name + ".exr", "test", notes});
  data::write_manifest(args.out_dir, m);
  log::info(notes);
  log::info("wrote " + args.out_dir + "/" + name + ".exr (depth " + c10::str(z_lo) + "-" + c10::str(z_hi) + " m) and manifest.json");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_import", kUsage,
               {"--rgb", "--disparity", "--name", "--scale", "--near-m", "--far-m", "--focal-px", "--baseline-m", "--doffs-px"},
               {}, true, true};
  return run_app(spec, argc, argv, run);
}
