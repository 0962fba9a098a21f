// hsd_bench data: the data path of training, measured in one run: generating
// synthetic scenes (per scene), loading a split with 1 and with N threads,
// building the patch sampler, drawing --patches patch specs and extracting
// (lighting included) patches of data.patch_size_px.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <unistd.h>

#include <torch/torch.h>

#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/dataset.h"
#include "data/illuminant_augment.h"
#include "data/measured_reflectances.h"
#include "data/patch_sampler.h"
#include "data/reflectance_library.h"
#include "data/scene_generator.h"
#include "data/synthetic_dataset.h"
#include "data/texture_bank.h"
#include "data/textured_scene.h"

namespace hsd::bench {

namespace {

// Each layout alone, generation only (no EXR or previews written): mean
// seconds per scene over 3 seeds.
std::map<std::string, double> seconds_per_layout(const GeneratorConfig& g, const std::vector<double>& bands, double bw) {
  const data::ReflectanceLibrary lib(bands, bw);
  const data::MeasuredReflectances measured(bands, bw, g.spectral_exclusion);
  const data::TextureBank textures(g.texture_dir.empty() ? data::TextureBank::default_dir() : g.texture_dir);
  const data::SceneSources src{measured, textures};
  std::map<std::string, double> t_layout;
  for (const SceneLayout layout : {SceneLayout::classic_tabletop, SceneLayout::tabletop, SceneLayout::dead_leaves}) {
    const auto t = std::chrono::steady_clock::now();
    for (uint64_t s = 1; s <= 3; ++s) {
      if (layout == SceneLayout::classic_tabletop) data::generate_tabletop_scene(g, lib, bands, s);
      else if (layout == SceneLayout::tabletop) data::generate_textured_tabletop_scene(g, src, bands, s);
      else data::generate_dead_leaves_scene(g, src, bands, s);
    }
    t_layout[choice_name(layout)] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count() / 3.0;
  }
  return t_layout;
}

// The EXR files' size in dir, MiB per scene.
double exr_mib_per_scene(const std::string& dir, int64_t scenes) {
  double b = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().extension() == ".exr") b += double(e.file_size());
  return b / double(scenes) / (1024.0 * 1024.0);
}

}  // namespace

int bench_data(Config cfg, const AppArgs& args, BenchOutput& out) {
  const int64_t scenes = args.integer("--scenes", 8), patches = args.integer("--patches", 20000);
  if (scenes < 1 || scenes > 1000) input_error("--scenes", "must be in [1, 1000]");
  if (patches < 1 || patches > 10000000) input_error("--patches", "must be in [1, 1e7]");
  auto& g = cfg.data.generator;
  g.train_scenes = scenes, g.val_scenes = 0, g.test_scenes = 0, g.colorchecker = false;
  const std::string dir = (std::filesystem::temp_directory_path() / ("hsd_bench_data_" + std::to_string(::getpid()))).string();
  std::filesystem::remove_all(dir);
  using clock = std::chrono::steady_clock;
  auto secs = [](clock::time_point a) { return std::chrono::duration<double>(clock::now() - a).count(); };
  const auto bands = cfg.optics.wavelengths_m();
  const double bw = cfg.optics.band_width_m();
  const int threads = torch::get_num_threads();

  log::info("generating " + std::to_string(scenes) + " scenes ...");
  auto t = clock::now();
  data::generate_dataset(cfg, dir);
  const double t_gen = secs(t) / double(scenes);
  const Json realism = Json::parse(read_text_file(dir + "/realism.json"));
  const std::map<std::string, double> t_layout = seconds_per_layout(g, bands, bw);
  const double mib = exr_mib_per_scene(dir, scenes);
  t = clock::now();
  const auto one = data::load_split(dir, "train", bands, bw, 1);
  const double t_load1 = secs(t);
  t = clock::now();
  const auto many = data::load_split(dir, "train", bands, bw, threads);
  const double t_loadn = secs(t);
  t = clock::now();
  const data::PatchSampler sampler(many, cfg.data.patch_size_px);
  const double t_sampler = secs(t);
  const data::IlluminantBank bank(cfg.data.illuminants, bands, bw);
  t = clock::now();
  const auto specs = sampler.draw(patches, cfg.seed, bank.size(), cfg.data.intensity_min, cfg.data.intensity_max);
  const double t_draw = secs(t);
  const int64_t n_extract = std::min<int64_t>(200, int64_t(specs.size()));
  t = clock::now();
  for (int64_t i = 0; i < n_extract; ++i) sampler.extract(specs[size_t(i)], &bank);
  const double t_extract = secs(t) / double(n_extract);
  std::filesystem::remove_all(dir);

  out.json = Json{{"bench", "data"}, {"threads", threads}, {"scenes", scenes}, {"width_px", g.width_px},
                  {"height_px", g.height_px}, {"bands", int64_t(bands.size())}, {"seconds_generate_per_scene", t_gen},
                  {"mib_per_scene_exr", mib}, {"seconds_load_1_thread", t_load1}, {"seconds_load_n_threads", t_loadn},
                  {"seconds_sampler_build", t_sampler}, {"sampler_candidates", sampler.candidates()},
                  {"sampler_depth_bins", sampler.depth_bins_used()}, {"patches", patches},
                  {"seconds_draw_patches", t_draw}, {"patch_px", cfg.data.patch_size_px},
                  {"seconds_extract_per_patch", t_extract}, {"realism_mean", realism["mean"]},
                  {"realism_targets", realism["targets"]}, {"realism_reference_cave", realism["reference"]},
                  {"seconds_generate_only", t_layout}};
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "data path: %lld scenes %lldx%lld, %zu bands, threads %d\n"
                "generate            %8.3f s per scene (%.1f MiB EXR each)\n"
                "load split          %8.3f s with 1 thread, %.3f s with %d (%.1fx)\n"
                "patch sampler       %8.3f s to build (%lld fully valid %lld px windows, %lld depth bins)\n"
                "draw %lld specs  %8.4f s\n"
                "extract + light     %8.4f s per %lld px patch\n",
                (long long)scenes, (long long)g.width_px, (long long)g.height_px, bands.size(), threads, t_gen, mib, t_load1,
                t_loadn, threads, t_load1 / std::max(1e-9, t_loadn), t_sampler, (long long)sampler.candidates(),
                (long long)cfg.data.patch_size_px, (long long)sampler.depth_bins_used(), (long long)patches, t_draw,
                t_extract, (long long)cfg.data.patch_size_px);
  out.text = buf;
  char b2[512];
  const Json& rm = realism["mean"];
  std::snprintf(b2, sizeof b2,
                "layouts alone       %8.3f s classic_tabletop, %.3f s tabletop, %.3f s dead_leaves per scene (no writing)\n"
                "realism (mean)      textured %.3f, PSD slope %.2f, PCs for 99 %% %lld, RGB-unexplained %.3f\n",
                t_layout.at("classic_tabletop"), t_layout.at("tabletop"), t_layout.at("dead_leaves"), rm["textured_fraction"].get<double>(),
                rm["psd_slope"].get<double>(), (long long)rm["pcs_99"].get<int64_t>(), rm["rgb_unexplained"].get<double>());
  out.text += b2;
  for (const auto& line : realism["targets"]) out.text += "  " + line.get<std::string>() + "\n";
  return 0;
}

}  // namespace hsd::bench
