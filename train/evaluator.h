// Evaluation of a trained system on whole scenes of a split (metrics.h): each
// scene is lit by sensor.illuminant (reflectance scenes), imaged through the
// trained DOE with the sensor model (noise from a fixed seed), reconstructed
// by the network, and compared with the truth. Writes pictures per scene
// (truth vs reconstruction in sRGB, error map, depth maps with colour bars,
// spectra at chosen points), the ColorChecker's 24-patch spectral plot, the
// DOE's PSF atlas, metrics.json and report.md.
#pragma once
#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "common/config.h"
#include "model/defocus_likelihood.h"
#include "model/spectral_wiener.h"
#include "train/trainer.h"

namespace hsd::train {

struct SceneMetrics {
  std::string file;
  double data_range = 0;  // PSNR/SSIM range: the scene's largest true radiance
  double hs_psnr_db = 0, hs_ssim = 0, lum_psnr_db = 0, lum_ssim = 0, depth_rmse_m = 0, depth_mae_m = 0;
  double colorchecker_rmse = -1;  // < 0: not a ColorChecker scene
  // Baselines on the same pixels (train/baselines.h); NaN when unknown.
  double baseline_constant_depth_rmse_m = std::nan(""), baseline_constant_depth_mae_m = std::nan("");
  double baseline_upsampling_hs_psnr_db = 0, baseline_upsampling_hs_ssim = 0;
  double baseline_wiener_hs_psnr_db = 0, baseline_wiener_hs_ssim = 0;  // Wiener deconvolution + upsampling
  // The spectral Wiener (LMMSE) cube (baselines.h); NaN when no prior is known.
  double baseline_spectral_wiener_hs_psnr_db = std::nan(""), baseline_spectral_wiener_hs_ssim = std::nan("");
  // A reference, not a baseline: the same LMMSE cube with each pixel's
  // rendering layer known (model/layered_spectral_wiener.h), what the depth
  // would add to the linear base; NaN when no prior is known.
  double depth_known_spectral_wiener_hs_psnr_db = std::nan("");
  // The network's residual base alone, no U-Net (model.spectral_map =
  // "learned": its learned map on its base; model.read_illuminant: the
  // spectral Wiener cube under the light read); NaN otherwise.
  double model_base_hs_psnr_db = std::nan(""), model_base_hs_ssim = std::nan("");
  // The illuminant reader's most probable light (a name of data.illuminants)
  // and its posterior weight; empty without model.read_illuminant.
  std::string illuminant_read;
  double illuminant_read_weight = std::nan("");
  // The resolution oracle (baselines.h) on the same pixels, one RMSE [m] per
  // window of kOracleWindowsPx; on the mean, the window whose oracle RMSE
  // equals the model's (its effective depth resolution, px; +inf: coarser than all).
  std::vector<double> oracle_depth_rmse_m;
  double depth_effective_resolution_px = std::nan("");
  // The layer oracle (baselines.h, layer_oracle_depth_map) on the same pixels:
  // what knowing each pixel's rendering layer, and nothing else, allows [m].
  double layer_oracle_depth_rmse_m = std::nan(""), layer_oracle_depth_mae_m = std::nan("");
  // The classical depth-from-defocus reader (kDefocusBaseline) on the same pixels [m].
  double baseline_defocus_depth_rmse_m = std::nan(""), baseline_defocus_depth_mae_m = std::nan("");
  // The same reader with the spectral prior (kSpectralDefocusWindowPx); NaN when no prior is known.
  double baseline_spectral_defocus_depth_rmse_m = std::nan(""), baseline_spectral_defocus_depth_mae_m = std::nan("");
  // The readings a fused depth combines (Reconstruction), each alone [m]; NaN when the depth is not fused.
  double network_depth_rmse_m = std::nan(""), network_depth_mae_m = std::nan("");
  double fused_reader_depth_rmse_m = std::nan(""), fused_reader_depth_mae_m = std::nan("");
  // The interior (metrics.h, interior_mask): the same metrics over the valid
  // pixels at least interior_margin_px (data.render_margin_px resolved, the
  // PSF's reach) from every border, where every training patch's pixels lie;
  // the PSNR's data range is the whole scene's. NaN when the scene has no
  // valid interior pixel or the metric is not reported; on the mean, the mean
  // over the scenes that have an interior (interior_scenes of them).
  int64_t interior_margin_px = 0, interior_scenes = 0;
  double interior_fraction = std::nan("");  // valid interior pixels / valid pixels
  double interior_hs_psnr_db = std::nan(""), interior_model_base_hs_psnr_db = std::nan("");
  double interior_baseline_upsampling_hs_psnr_db = std::nan(""), interior_baseline_spectral_wiener_hs_psnr_db = std::nan("");
  double interior_depth_rmse_m = std::nan(""), interior_baseline_constant_depth_rmse_m = std::nan("");
};

// The classical depth-from-defocus baseline's model (model/defocus_likelihood.h):
// ρ = 0.3 and a 31-px window, the best of ρ ∈ {1e-4, 1e-3, 1e-2, 3e-2, 0.1,
// 0.3} and windows {7, 15, 31, 63} px on the validation split of the shipped
// quick model's seed 0 (docs/learning.md, "A classical reader of the cue").
inline const model::DefocusModel kDefocusBaseline{0.3, 1.0 / 64, 31};
// The spectral reader's box (model::spectral_defocus_cost_volume): 31 px, the
// better of {5, 9, 15, 31} px on the validation splits of the shipped quick
// model's three seeds (mean 0.83x the constant against 0.84x at 15 px).
inline constexpr int64_t kSpectralDefocusWindowPx = model::kDefocusReaderWindowPx;

// The resolution oracle's windows [px] in every evaluation.
inline const std::vector<int64_t> kOracleWindowsPx{3, 5, 9, 15, 31, 63, 127};
// One sentence on the spectral Wiener baseline of m (its PSNR and SSIM, the model's distance from it).
std::string spectral_wiener_summary(const SceneMetrics& m);
// One sentence on the interior's metrics of m (interior_*) against its baselines, led by a blank line.
std::string interior_summary(const SceneMetrics& m);
// An effective resolution as text: "52 px", or "more than 127 px" when coarser than every window.
std::string effective_resolution_text(double px);

struct EvalResult {
  std::vector<SceneMetrics> scenes;
  SceneMetrics mean;  // means over the scenes (colorchecker_rmse over ColorChecker scenes)
};

// What a reconstructor returns for a sensor image [B, 3, H, W]: the cube
// [B, L, H, W] and the depth [B, 1, H, W] metres; for a depth that fuses two
// readings (model.fuse_defocus_reader), each reading alone [B, 1, H, W]
// metres, scored beside it (undefined: not reported). A (cube, depth) pair
// converts to one.
struct Reconstruction {
  torch::Tensor hs, depth_m;
  torch::Tensor network_depth_m, reader_depth_m;
  // Optional: the network's residual base alone [B, L, H, W] (scored as
  // model_base_*), and the illuminant reader's posterior [B, K] over
  // data.illuminants (model.read_illuminant; written per scene).
  torch::Tensor base_hs, illuminant_weights;
  Reconstruction(std::pair<torch::Tensor, torch::Tensor> p) : hs(std::move(p.first)), depth_m(std::move(p.second)) {}
  Reconstruction(torch::Tensor h, torch::Tensor d, torch::Tensor network = {}, torch::Tensor reader = {})
      : hs(std::move(h)), depth_m(std::move(d)), network_depth_m(std::move(network)), reader_depth_m(std::move(reader)) {}
};
using Reconstructor = std::function<Reconstruction(const torch::Tensor&)>;

// The optics (PSF simulator, sensor model, DOE height [N, N]; or a fixed PSF
// stack through `fixed_psf`: the all-in-focus control, a PSF file) image each
// scene; `reconstruct` recovers it. Every metric is over the scene's valid pixels.
// Beside the model, the baselines on the same pixels: the spectral-upsampling
// cube of the same sensor image, its Wiener deconvolution with `model_psf`
// [L, Z, P, P] (the PSFs the system believes it has; undefined = the imaging
// PSFs), and the constant depth 1 / baseline_inv_depth [1/m] (NaN: not
// reported, with a warning). `model_map` [L, 3]: a learned spectral map of the
// network's residual (model.spectral_map = "learned"), scored on its residual
// base (cfg.model.residual) alone; undefined: not reported. `sw_prior`: the
// spectral Wiener baseline's prior (training_spectral_prior; the camera's
// response is the sensor's); nullptr: not reported.
EvalResult evaluate(const optics::PsfSimulator& psf, const optics::SensorModel& sensor, const torch::Tensor& height_m,
                    const Reconstructor& reconstruct, const Config& cfg, const std::string& split,
                    const std::string& out_dir, double baseline_inv_depth = std::nan(""),
                    const optics::PsfProvider& fixed_psf = nullptr, const torch::Tensor& model_psf = {},
                    const torch::Tensor& model_map = {}, const model::SpectralPrior* sw_prior = nullptr);

// The same with a trainer's optics, DOE and network (load a checkpoint first).
// The spectral Wiener baseline's prior: the network's own (model.residual =
// "spectral_wiener"), else the training split of data.root when it has one.
// `camera_psf` (a fixed provider, e.g. of a measured or perturbed PSF file):
// the scenes are imaged through it instead of the trainer's PSFs, while the
// network (its Wiener pre-inversion) and the Wiener baseline keep the
// trainer's: a system evaluated through a camera that differs from its model.
// calibrated = true: the network's pre-inversion and spectral Wiener filter and
// the Wiener baselines use the camera's PSFs as well (a camera whose PSFs were
// measured after it was made, hsd_calibrate), with the network's weights as trained.
EvalResult evaluate(Trainer& trainer, const Config& cfg, const std::string& split, const std::string& out_dir,
                    const optics::PsfProvider& camera_psf = nullptr, bool calibrated = false);

}  // namespace hsd::train
