// hsd_eval: metrics and pictures of a trained system on a split
// (train/evaluator.h): DIR/metrics.json (docs/formats.md keys, per scene and
// mean), DIR/report.md, per-scene comparisons and spectra, the ColorChecker
// spectral plot and the DOE's PSF atlas.
#include <cmath>
#include <filesystem>
#include <map>

#include <torch/script.h>
#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/manifest.h"
#include "model/torchscript_export.h"
#include "optics/doe.h"
#include "optics/psf.h"
#include "optics/psf_file.h"
#include "optics/psf_source.h"
#include "optics/sensor.h"
#include "train/evaluator.h"
#include "train/trainer.h"
#include "usage/hsd_eval.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

// The log's summary: the mean metrics with the baselines beside each, their
// ratios, and the depth's effective resolution.
void log_summary(const train::EvalResult& r, const std::string& split) {
  char buf[1200];
  const auto& a = r.mean;
  std::snprintf(buf, sizeof buf,
                "mean over %zu %s scenes (baselines in brackets): HS PSNR %.2f dB (upsampling alone %.2f dB; Wiener "
                "deconvolution + upsampling %.2f dB), SSIM %.4f (%.4f; %.4f); depth RMSE %.4f m (constant depth %.4f m), "
                "MAE %.4f m (%.4f m)",
                r.scenes.size(), split.c_str(), a.hs_psnr_db, a.baseline_upsampling_hs_psnr_db,
                a.baseline_wiener_hs_psnr_db, a.hs_ssim, a.baseline_upsampling_hs_ssim, a.baseline_wiener_hs_ssim,
                a.depth_rmse_m, a.baseline_constant_depth_rmse_m, a.depth_mae_m, a.baseline_constant_depth_mae_m);
  log::info(buf);
  if (std::isfinite(a.baseline_constant_depth_rmse_m) && a.baseline_constant_depth_rmse_m > 0) {
    std::snprintf(buf, sizeof buf,
                  "against the baselines: depth RMSE %.2f x the constant's; HS PSNR %+.2f dB over upsampling alone, "
                  "%+.2f dB over Wiener + upsampling",
                  a.depth_rmse_m / a.baseline_constant_depth_rmse_m, a.hs_psnr_db - a.baseline_upsampling_hs_psnr_db,
                  a.hs_psnr_db - a.baseline_wiener_hs_psnr_db);
    log::info(buf);
  }
  if (std::isfinite(a.baseline_spectral_wiener_hs_psnr_db)) log::info(train::spectral_wiener_summary(a));
  if (std::isfinite(a.model_base_hs_psnr_db)) {
    std::map<std::string, int> lights;  // the illuminant reader's most probable light per scene
    for (const auto& m : r.scenes)
      if (!m.illuminant_read.empty()) ++lights[m.illuminant_read];
    std::string read;
    for (const auto& [name, n] : lights) read += (read.empty() ? "" : ", ") + name + " " + std::to_string(n);
    std::snprintf(buf, sizeof buf, "the network's residual base alone (%s, no U-Net): HS PSNR %.2f dB, SSIM %.4f; "
                  "the U-Net adds %+.2f dB%s%s",
                  lights.empty() ? "its learned spectral map"
                                 : "the spectral Wiener cube under the light the illuminant reader read",
                  a.model_base_hs_psnr_db, a.model_base_hs_ssim, a.hs_psnr_db - a.model_base_hs_psnr_db,
                  lights.empty() ? "" : "; lights read (scenes): ", read.c_str());
    log::info(buf);
  }
  if (std::isfinite(a.baseline_defocus_depth_rmse_m)) {
    std::snprintf(buf, sizeof buf,
                  "the classical depth-from-defocus reader (the layer of least local likelihood, no learning; "
                  "report.md): depth RMSE %.4f m, MAE %.4f m",
                  a.baseline_defocus_depth_rmse_m, a.baseline_defocus_depth_mae_m);
    log::info(buf);
  }
  if (std::isfinite(a.baseline_spectral_defocus_depth_rmse_m)) {
    std::snprintf(buf, sizeof buf,
                  "the same reader with the spectral prior (colour and depth read together, no learning): depth RMSE "
                  "%.4f m, MAE %.4f m; the model's depth RMSE is %.2f x its",
                  a.baseline_spectral_defocus_depth_rmse_m, a.baseline_spectral_defocus_depth_mae_m,
                  a.depth_rmse_m / std::max(1e-12, a.baseline_spectral_defocus_depth_rmse_m));
    log::info(buf);
  }
  if (std::isfinite(a.network_depth_rmse_m)) {
    std::snprintf(buf, sizeof buf,
                  "the depth output fuses two readings (report.md): the network's alone RMSE %.4f m, the reader's as "
                  "fused %.4f m; fused %.4f m, %.2f x the network's alone",
                  a.network_depth_rmse_m, a.fused_reader_depth_rmse_m, a.depth_rmse_m,
                  a.depth_rmse_m / std::max(1e-12, a.network_depth_rmse_m));
    log::info(buf);
  }
  if (std::isfinite(a.layer_oracle_depth_rmse_m)) {
    std::snprintf(buf, sizeof buf,
                  "the layer oracle (each pixel at its scene's mean depth in its rendering layer; report.md): depth "
                  "RMSE %.4f m, MAE %.4f m",
                  a.layer_oracle_depth_rmse_m, a.layer_oracle_depth_mae_m);
    log::info(buf);
  }
  {
    std::string interior = train::interior_summary(a);
    log::info(interior.substr(interior.find_first_not_of('\n')));
  }
  if (!std::isnan(a.depth_effective_resolution_px)) {
    std::snprintf(buf, sizeof buf,
                  "the depth RMSE equals that of the true depth averaged over a box of %s (the resolution oracle, "
                  "report.md): depth structure finer than that is not recovered",
                  train::effective_resolution_text(a.depth_effective_resolution_px).c_str());
    log::info(buf);
  }
}

int run(const AppArgs& args) {
  std::vector<std::string> overrides = args.overrides;
  if (args.has("--data")) {
    const std::string dir = args.option("--data", "");
    if (!data::has_manifest(dir)) input_error("--data", "\"" + dir + "\" holds no manifest.json (hsd_scenes writes one)");
    overrides.push_back("data.root=" + Json(dir).dump());
  }
  const Config cfg = load_config(args.config_path, overrides);
  const std::string ckpt = args.option("--checkpoint", ""), model_path = args.option("--model", "");
  if (ckpt.empty() == model_path.empty())
    input_error("--checkpoint/--model", "give exactly one: a training checkpoint or an exported reconstructor.pt");
  const std::string split = args.option("--split", "test");
  if (split != "train" && split != "val" && split != "test" && split != "all")
    input_error("--split", "expected train, val, test or all, got \"" + split + "\"");
  make_dirs(args.out_dir);
  check_output_paths({args.out_dir + "/metrics.json", args.out_dir + "/report.md", args.out_dir + "/config.json"});
  optics::PsfProvider camera;  // --camera-psf: the scenes imaged through another stack
  if (args.has("--camera-psf")) {
    const std::string f = args.option("--camera-psf", "");
    camera = optics::fixed_psf_provider(optics::psf_for_config(optics::read_psf_file(f), cfg.optics, f, "--camera-psf", torch::kCPU));
    log::info("imaging through the camera PSFs of " + f + "; the reconstructor keeps the config's");
  }
  train::EvalResult r;
  if (!ckpt.empty()) {
    if (!std::filesystem::is_regular_file(ckpt)) input_error(ckpt, "no such checkpoint file (--checkpoint)");
    setup_threads(cfg.threads);
    train::Trainer trainer(cfg);
    trainer.load_checkpoint(ckpt);
    r = train::evaluate(trainer, cfg, split, args.out_dir, camera);
  } else {
    // An exported model: the DOE it expects travels beside it (doe_height.pt), or --doe.
    torch::jit::Module m = model::load_reconstructor(model_path);  // the model first: it is what the user named
    const std::string doe = args.option("--doe", (std::filesystem::path(model_path).parent_path() / "doe_height.pt").string());
    if (!std::filesystem::exists(doe)) input_error(doe, "no DOE height file for the model (hsd_export writes doe_height.pt; or --doe PATH)");
    if (m.attr("wavelengths_m").toTensor().numel() != int64_t(cfg.optics.wavelengths_nm.size()))
      input_error(model_path, "its wavelengths_m do not match optics.wavelengths_nm of the config");
    setup_threads(cfg.threads);
    const auto material = optics::Material::load(cfg.optics.material);
    const optics::PsfSimulator sim(optics::make_psf_spec(cfg.optics, material, torch::kCPU));
    const optics::SensorModel sensor = optics::make_sensor_model(cfg.sensor, sim.spec(), cfg.optics.band_width_m());
    const torch::Tensor h = optics::load_height_file(doe, cfg.optics.doe_samples, cfg.optics.doe_pitch_m);
    auto net = [&](const torch::Tensor& x) { return model::run_reconstructor(m, x); };
    double inv = std::nan("");
    if (m.hasattr("baseline_inv_depth_per_m")) {
      const c10::IValue v = m.attr("baseline_inv_depth_per_m");
      if (!v.isDouble() || !(v.toDouble() > 0) || !std::isfinite(v.toDouble()))
        input_error(model_path, "attribute baseline_inv_depth_per_m must be a finite positive number");
      inv = v.toDouble();
    }
    const optics::PsfProvider own = optics::psf_source_provider(cfg.optics, material, torch::kCPU);
    const torch::Tensor model_psf = camera ? optics::imaging_psf_stack(sim, h, own) : torch::Tensor();
    // A learned spectral map travels in the model as its parameter p_upsampling_weights.
    torch::Tensor model_map;
    if (cfg.model.spectral_map == SpectralMap::learned && m.hasattr("p_upsampling_weights"))
      model_map = m.attr("p_upsampling_weights").toTensor().detach().to(torch::kFloat32);
    r = train::evaluate(sim, sensor, h, net, cfg, split, args.out_dir, inv, camera ? camera : own, model_psf, model_map);
  }
  write_resolved_config(cfg, args.out_dir);
  log_summary(r, split);
  log::info("wrote " + args.out_dir + "/metrics.json, report.md and pictures");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_eval", kUsage, {"--checkpoint", "--model", "--split", "--doe", "--data", "--camera-psf"}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
