#include "train/evaluator.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>

#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "data/dataset.h"
#include "data/depth_structure.h"
#include "data/image_io.h"
#include "data/manifest.h"
#include "data/preview.h"
#include "model/defocus_likelihood.h"
#include "model/layered_spectral_wiener.h"
#include "model/spectral_upsampling.h"
#include "model/wiener_preinverse.h"
#include "optics/psf_source.h"
#include "optics/sensor_image.h"
#include "optics/spectrum.h"
#include "train/baselines.h"
#include "train/metrics.h"
#include "viz/plot.h"
#include "viz/psf_atlas.h"

namespace hsd::train {

namespace {

std::vector<std::array<int64_t, 4>> read_boxes(const std::string& path, std::vector<std::string>* names) {
  std::vector<std::array<int64_t, 4>> boxes;
  const Json j = read_json_file(path);
  try {
    for (const auto& p : j.at("patches")) {
      const auto b = p.at("box_xyxy");
      boxes.push_back({b[0].get<int64_t>(), b[1].get<int64_t>(), b[2].get<int64_t>(), b[3].get<int64_t>()});
      if (names) names->push_back(p.at("name").get<std::string>());
    }
  } catch (const Json::exception& e) {
    input_error(path, std::string("malformed ColorChecker layout (") + e.what() + ")");
  }
  return boxes;
}

}  // namespace

std::string spectral_wiener_summary(const SceneMetrics& m) {
  char buf[300];
  std::snprintf(buf, sizeof buf,
                "the spectral Wiener baseline (the LMMSE cube under the training split's spectral statistics, no "
                "network): HS PSNR %.2f dB, SSIM %.4f; the model is %+.2f dB from it",
                m.baseline_spectral_wiener_hs_psnr_db, m.baseline_spectral_wiener_hs_ssim,
                m.hs_psnr_db - m.baseline_spectral_wiener_hs_psnr_db);
  std::string out = buf;
  if (std::isfinite(m.depth_known_spectral_wiener_hs_psnr_db)) {
    std::snprintf(buf, sizeof buf, "; with each pixel's rendering layer known it would score %.2f dB (a reference: what "
                  "the depth adds to the linear cube)", m.depth_known_spectral_wiener_hs_psnr_db);
    out += buf;
  }
  return out;
}

std::string interior_summary(const SceneMetrics& m) {
  char buf[700];
  if (m.interior_scenes == 0) {
    std::snprintf(buf, sizeof buf, "\nThe interior (the valid pixels at least %lld px from every border): no scene has "
                  "one; every pixel lies within the PSF's reach of its scene's border.\n", (long long)m.interior_margin_px);
    return buf;
  }
  std::snprintf(buf, sizeof buf,
                "\nThe interior (interior_*: the valid pixels at least %lld px, the rendering margin, from every border, "
                "where every training patch's pixels lie; %.0f %% of the valid pixels), mean over %lld scenes: HS PSNR "
                "%.2f dB (upsampling alone %.2f dB, %+.2f dB over it)",
                (long long)m.interior_margin_px, 100.0 * m.interior_fraction, (long long)m.interior_scenes,
                m.interior_hs_psnr_db, m.interior_baseline_upsampling_hs_psnr_db,
                m.interior_hs_psnr_db - m.interior_baseline_upsampling_hs_psnr_db);
  std::string out = buf;
  if (std::isfinite(m.interior_baseline_spectral_wiener_hs_psnr_db)) {
    std::snprintf(buf, sizeof buf, "; the spectral Wiener baseline %.2f dB", m.interior_baseline_spectral_wiener_hs_psnr_db);
    out += buf;
  }
  if (std::isfinite(m.interior_model_base_hs_psnr_db)) {
    std::snprintf(buf, sizeof buf, "; the network's residual base alone %.2f dB, the U-Net adds %+.2f dB to it",
                  m.interior_model_base_hs_psnr_db, m.interior_hs_psnr_db - m.interior_model_base_hs_psnr_db);
    out += buf;
  }
  std::snprintf(buf, sizeof buf, "; depth RMSE %.4f m", m.interior_depth_rmse_m);
  out += buf;
  if (std::isfinite(m.interior_baseline_constant_depth_rmse_m) && m.interior_baseline_constant_depth_rmse_m > 0) {
    std::snprintf(buf, sizeof buf, " (the constant %.4f m, %.2f x it)", m.interior_baseline_constant_depth_rmse_m,
                  m.interior_depth_rmse_m / m.interior_baseline_constant_depth_rmse_m);
    out += buf;
  }
  return out + ".";
}

std::string effective_resolution_text(double px) {
  return std::isfinite(px) ? std::to_string(std::lround(px)) + " px"
                           : "more than " + std::to_string(kOracleWindowsPx.back()) + " px";
}

EvalResult evaluate(Trainer& trainer, const Config& cfg, const std::string& split, const std::string& out_dir,
                    const optics::PsfProvider& camera_psf, bool calibrated) {
  trainer.net()->eval();
  trainer.refresh_preinverse();
  trainer.ensure_illuminant_moments();  // model.read_illuminant: from the training split
  torch::Tensor model_psf;  // the PSFs the network's inputs and the Wiener baselines use (with a camera_psf)
  if (camera_psf && !calibrated) model_psf = trainer.psf_stack();
  if (camera_psf && calibrated) {  // the network's linear inputs from the camera's PSFs
    torch::NoGradGuard no_grad;
    model_psf = optics::imaging_psf_stack(trainer.psf(), trainer.doe().height().detach(), camera_psf);
    if (trainer.net()->options().preinverse_layers > 0)
      trainer.net()->set_preinverse_psf(model::camera_rgb_psfs(model_psf, trainer.sensor().omega));
    if (trainer.net()->options().residual_spectral_wiener) trainer.net()->set_band_psf(model_psf);
  }
  auto net = [&](const torch::Tensor& x) {
    // With the illuminant reader, its base is computed once: handed to the network and scored alone.
    const bool read = trainer.net()->options().read_illuminant;
    const torch::Tensor base = read ? trainer.net()->spectral_wiener(x) : torch::Tensor();
    const model::NetOutput o = trainer.net()->forward(x, {}, base);
    Reconstruction r(o.hs, o.depth_m, o.network_depth_m, o.reader_depth_m);
    if (read) r.base_hs = base, r.illuminant_weights = trainer.net()->illuminant_posterior(x);
    return r;
  };
  const torch::Tensor model_map = trainer.net()->options().learned_spectral_map
                                      ? trainer.net()->upsampling_weights().detach().cpu()
                                      : torch::Tensor();
  std::optional<model::SpectralPrior> prior;
  if (trainer.net()->options().residual_spectral_wiener) {
    prior = trainer.net()->spectral_prior();
  } else if (data::has_manifest(cfg.data.root) && !data::read_manifest(cfg.data.root).split("train").empty()) {
    const auto scenes = data::load_split(cfg.data.root, "train", cfg.optics.wavelengths_m(), cfg.optics.band_width_m(),
                                         cfg.data.loader_threads);
    prior = training_spectral_prior(scenes, cfg, trainer.sensor());
  }
  EvalResult r = evaluate(trainer.psf(), trainer.sensor(), trainer.doe().height().detach(), net, cfg, split, out_dir,
                          trainer.baseline_inv_depth(), camera_psf ? camera_psf : trainer.fixed_psf(), model_psf, model_map,
                          prior ? &*prior : nullptr);
  if (camera_psf && calibrated) trainer.refresh_preinverse();  // the design's PSFs again
  trainer.net()->train();
  return r;
}

EvalResult evaluate(const optics::PsfSimulator& psf, const optics::SensorModel& sensor, const torch::Tensor& height_m,
                    const Reconstructor& reconstruct, const Config& cfg, const std::string& split,
                    const std::string& out_dir, double baseline_inv_depth, const optics::PsfProvider& fixed_psf,
                    const torch::Tensor& model_psf, const torch::Tensor& model_map, const model::SpectralPrior* sw_prior) {
  const std::string root = cfg.data.root;
  const auto bands = cfg.optics.wavelengths_m();
  const double bw = cfg.optics.band_width_m();
  const auto scenes = data::load_split(root, split, bands, bw, cfg.data.loader_threads);
  const torch::Tensor E = optics::illuminant_bands(cfg.sensor.illuminant, bands, bw);
  const torch::Tensor ybar = data::cmf_bands(bands, bw)[1].to(torch::kFloat32);
  const auto& g = cfg.data.generator;
  const double near = std::min(g.depth_min_m, cfg.optics.depths_m.front()), far = std::max(g.depth_max_m, cfg.optics.depths_m.back());
  make_dirs(out_dir);
  torch::NoGradGuard no_grad;
  const torch::Tensor h = height_m.detach();
  EvalResult res;
  const bool constant_known = std::isfinite(baseline_inv_depth) && baseline_inv_depth > 0;
  if (!constant_known)
    log::warn("no constant-depth baseline: the checkpoint or model does not store the training split's median inverse "
              "depth (made by an earlier hsd); retrain, or evaluate with a checkpoint of this version");
  const torch::Tensor up_w = model::spectral_upsampling_weights(sensor.omega.cpu());
  if (model_map.defined() && !(model_map.dim() == 2 && model_map.size(0) == up_w.size(0) && model_map.size(1) == up_w.size(1)))
    throw InputError("the model's spectral map must be [" + std::to_string(up_w.size(0)) + ", " +
                     std::to_string(up_w.size(1)) + "] (optics.wavelengths_nm x RGB), got " + c10::str(model_map.sizes()));
  const torch::Tensor imaging_psf = optics::imaging_psf_stack(psf, h, fixed_psf).cpu();
  const torch::Tensor band_psf = model_psf.defined() ? model_psf.detach().cpu() : imaging_psf;
  const torch::Tensor omega = sensor.omega.cpu();
  const torch::Tensor rgb_psf = model::camera_rgb_psfs(band_psf, omega);
  const int64_t K = int64_t(psf.spec().depths_m.size());
  if (sw_prior && band_psf.size(1) != K)  // the depth-known reference picks layers by optics.depths_m
    throw InputError("the model's band PSFs have " + std::to_string(band_psf.size(1)) + " depth layers, optics.depths_m " +
                     std::to_string(K));
  int cc_count = 0;
  double cc_sum = 0.0;
  const int64_t interior_margin = render_margin_px(cfg);
  log::Progress progress("evaluate", long(scenes.size()));
  for (size_t i = 0; i < scenes.size(); ++i) {
    const auto& ls = scenes[i];
    const auto& sc = ls.scene;
    const torch::Tensor radiance = sc.kind == data::SpectralKind::Reflectance ? sc.spectral * E.view({-1, 1, 1}) : sc.spectral;
    auto gen = at::detail::createCPUGenerator(cfg.seed + 7919 * (i + 1));
    const optics::SensorImage img = optics::simulate_sensor(psf, sensor, h, radiance.unsqueeze(0),
                                                            sc.depth_m.unsqueeze(0), gen, optics::LeaveOut(), fixed_psf);
    const auto out = reconstruct(img.image);
    const torch::Tensor hs = out.hs[0].cpu(), dp = out.depth_m[0].cpu();
    for (const auto& [t, what] : {std::pair<const torch::Tensor&, const char*>{hs, "cube"}, {dp, "depth map"}}) {
      const std::string bad = first_nonfinite(t);
      if (!bad.empty())
        throw NumericalError("the model's " + std::string(what) + " for " + ls.file + " holds " + bad +
                             " (a damaged or diverged model; no metrics written)");
    }
    SceneMetrics m;
    m.file = ls.file;
    m.data_range = std::max(1e-12, radiance.max().item<double>());
    const torch::Tensor& valid = sc.mask;
    // The interior: the valid pixels beyond the PSF's reach of the border (metrics.h).
    m.interior_margin_px = interior_margin;
    const torch::Tensor inner = interior_mask(valid, interior_margin);
    const double n_valid = (valid > 0.5).sum().item<double>(), n_inner = inner.sum().item<double>();
    const bool has_inner = n_inner > 0;
    if (n_valid > 0) m.interior_fraction = n_inner / n_valid;
    auto inner_psnr = [&](const torch::Tensor& cube) {
      return has_inner ? psnr_db(cube, radiance, m.data_range, inner) : std::nan("");
    };
    auto inner_rmse = [&](const torch::Tensor& d) {
      return has_inner ? depth_errors(d, sc.depth_m, inner).rmse_m : std::nan("");
    };
    m.hs_psnr_db = psnr_db(hs, radiance, m.data_range, valid);
    m.interior_hs_psnr_db = inner_psnr(hs);
    m.hs_ssim = ssim(hs, radiance, m.data_range, valid);
    const torch::Tensor Yt = luminance(radiance, ybar), Yp = luminance(hs, ybar);
    const double yr = std::max(1e-12, Yt.max().item<double>());
    m.lum_psnr_db = psnr_db(Yp, Yt, yr, valid);
    m.lum_ssim = ssim(Yp, Yt, yr, valid);
    const DepthErrors de = depth_errors(dp, sc.depth_m, valid);
    m.depth_rmse_m = de.rmse_m, m.depth_mae_m = de.mae_m;
    m.interior_depth_rmse_m = inner_rmse(dp);
    if (out.network_depth_m.defined() && out.reader_depth_m.defined()) {  // the fused depth's two readings alone
      const DepthErrors dn = depth_errors(out.network_depth_m[0].cpu(), sc.depth_m, valid);
      const DepthErrors dr = depth_errors(out.reader_depth_m[0].cpu(), sc.depth_m, valid);
      m.network_depth_rmse_m = dn.rmse_m, m.network_depth_mae_m = dn.mae_m;
      m.fused_reader_depth_rmse_m = dr.rmse_m, m.fused_reader_depth_mae_m = dr.mae_m;
    }
    // The baselines on the same pixels.
    const torch::Tensor up = model::spectral_upsample(up_w, img.image.cpu())[0];
    m.baseline_upsampling_hs_psnr_db = psnr_db(up, radiance, m.data_range, valid);
    m.baseline_upsampling_hs_ssim = ssim(up, radiance, m.data_range, valid);
    m.interior_baseline_upsampling_hs_psnr_db = inner_psnr(up);
    // The Wiener baseline's image once: upsampled by the fixed map here, by a learned one below.
    const torch::Tensor wmean = wiener_mean_image(img.image.cpu(), rgb_psf, cfg.model.preinverse_reg);
    const torch::Tensor wup = model::spectral_upsample(up_w, wmean)[0];
    m.baseline_wiener_hs_psnr_db = psnr_db(wup, radiance, m.data_range, valid);
    m.baseline_wiener_hs_ssim = ssim(wup, radiance, m.data_range, valid);
    if (sw_prior) {  // the spectral Wiener (LMMSE) cube through the PSFs the system believes it has
      const torch::Tensor y = img.image.cpu();
      const model::SpectralOtf otf = model::spectral_otf(band_psf, y.size(2), y.size(3));  // both cubes' OTFs
      const torch::Tensor sw = model::apply_spectral_wiener(model::spectral_wiener_filter(otf, omega, *sw_prior), y)[0];
      m.baseline_spectral_wiener_hs_psnr_db = psnr_db(sw, radiance, m.data_range, valid);
      m.baseline_spectral_wiener_hs_ssim = ssim(sw, radiance, m.data_range, valid);
      m.interior_baseline_spectral_wiener_hs_psnr_db = inner_psnr(sw);
      // The same LMMSE cube with each pixel's rendering layer known: what the
      // linear base would gain from the depth (model/layered_spectral_wiener.h).
      const torch::Tensor known =
          model::one_hot_layer_weights(optics::nearest_layer(sc.depth_m.unsqueeze(0), psf.spec().depths_m), K);
      m.depth_known_spectral_wiener_hs_psnr_db = psnr_db(
          model::layered_spectral_wiener_cube(y, otf, omega, *sw_prior, known)[0], radiance, m.data_range, valid);
    }
    if (model_map.defined()) {  // the network's own residual base, no U-Net
      const torch::Tensor base = cfg.model.residual == ResidualBase::preinverse ? wmean : img.image.cpu();
      const torch::Tensor mb = model::spectral_upsample(model_map.to(torch::kFloat32), base)[0];
      m.model_base_hs_psnr_db = psnr_db(mb, radiance, m.data_range, valid);
      m.model_base_hs_ssim = ssim(mb, radiance, m.data_range, valid);
      m.interior_model_base_hs_psnr_db = inner_psnr(mb);
    } else if (out.base_hs.defined()) {  // the base the reconstructor gave (the illuminant reader's spectral Wiener cube)
      const torch::Tensor mb = out.base_hs[0].cpu();
      m.model_base_hs_psnr_db = psnr_db(mb, radiance, m.data_range, valid);
      m.model_base_hs_ssim = ssim(mb, radiance, m.data_range, valid);
      m.interior_model_base_hs_psnr_db = inner_psnr(mb);
    }
    if (out.illuminant_weights.defined() && out.illuminant_weights.size(-1) == int64_t(cfg.data.illuminants.size())) {
      const torch::Tensor w = out.illuminant_weights.reshape({-1}).cpu();
      const int64_t k = w.argmax().item<int64_t>();
      m.illuminant_read = cfg.data.illuminants[size_t(k)];
      m.illuminant_read_weight = w[k].item<double>();
    }
    if (constant_known) {
      const torch::Tensor constant = constant_depth_map(sc.depth_m, baseline_inv_depth);
      const DepthErrors dc = depth_errors(constant, sc.depth_m, valid);
      m.baseline_constant_depth_rmse_m = dc.rmse_m, m.baseline_constant_depth_mae_m = dc.mae_m;
      m.interior_baseline_constant_depth_rmse_m = inner_rmse(constant);
    }
    // The classical depth-from-defocus reader on the same image and PSFs as the network's inputs.
    const torch::Tensor dfd =
        model::defocus_layer_depth(model::defocus_cost_volume(img.image.cpu(), rgb_psf, kDefocusBaseline), psf.spec().depths_m);  // [1, H, W]
    const DepthErrors dd = depth_errors(dfd, sc.depth_m, valid);
    m.baseline_defocus_depth_rmse_m = dd.rmse_m, m.baseline_defocus_depth_mae_m = dd.mae_m;
    if (sw_prior) {  // the same reader with the spectral prior and band PSFs of the spectral Wiener baseline
      const torch::Tensor c = model::spectral_defocus_cost_volume(img.image.cpu(), band_psf, omega, *sw_prior,
                                                                  kSpectralDefocusWindowPx);
      const DepthErrors ds = depth_errors(model::defocus_layer_depth(c, psf.spec().depths_m), sc.depth_m, valid);
      m.baseline_spectral_defocus_depth_rmse_m = ds.rmse_m, m.baseline_spectral_defocus_depth_mae_m = ds.mae_m;
    }
    const DepthErrors dl = depth_errors(layer_oracle_depth_map(sc.depth_m, valid, psf.spec().depths_m), sc.depth_m, valid);
    m.layer_oracle_depth_rmse_m = dl.rmse_m, m.layer_oracle_depth_mae_m = dl.mae_m;
    for (int64_t w : kOracleWindowsPx)
      m.oracle_depth_rmse_m.push_back(depth_errors(data::box_oracle_depth_map(sc.depth_m, valid, w), sc.depth_m, valid).rmse_m);
    const std::string stem = out_dir + "/" + std::filesystem::path(ls.file).stem().string();
    // Pictures: truth | reconstruction | |error| x4 | true depth | predicted depth.
    const torch::Tensor truth_rgb = data::spectral_to_linear_srgb(radiance, bands, bw);
    const double white = std::max(1e-6, truth_rgb.max().item<double>());
    data::write_srgb_png(stem + "_a.png", truth_rgb, white);
    data::write_srgb_png(stem + "_b.png", data::spectral_to_linear_srgb(hs.clamp_min(0), bands, bw), white);
    data::write_srgb_png(stem + "_c.png", (hs - radiance).abs().mean(0, true).expand({3, -1, -1}), 0.25 * m.data_range);
    data::write_depth_png(stem + "_d.png", sc.depth_m, sc.mask, near, far);
    data::write_depth_png(stem + "_e.png", dp, {}, near, far);
    viz::write_montage({stem + "_a.png", stem + "_b.png", stem + "_c.png", stem + "_d.png", stem + "_e.png"}, 5, 1.0,
            stem + "_compare.png");
    // Spectra at three valid points (the centre and two drawn with the seed).
    std::vector<std::pair<int64_t, int64_t>> pts{{sc.spectral.size(1) / 2, sc.spectral.size(2) / 2}};
    std::mt19937_64 rng(cfg.seed + i);
    while (pts.size() < 3) {
      const int64_t y = int64_t(rng() % uint64_t(sc.spectral.size(1))), x = int64_t(rng() % uint64_t(sc.spectral.size(2)));
      if (sc.mask[0][y][x].item<float>() > 0.5f) pts.push_back({y, x});
    }
    std::vector<viz::Series> series;
    const std::array<std::array<int, 3>, 3> colours{{{200, 60, 30}, {30, 150, 30}, {30, 30, 200}}};
    std::vector<double> wl(cfg.optics.wavelengths_nm.begin(), cfg.optics.wavelengths_nm.end());
    for (size_t k = 0; k < pts.size(); ++k) {
      const auto [y, x] = pts[k];
      std::vector<double> t, p;
      for (int64_t l = 0; l < radiance.size(0); ++l) t.push_back(radiance[l][y][x].item<double>()), p.push_back(hs[l][y][x].item<double>());
      char name[64];
      std::snprintf(name, sizeof name, "(%lld,%lld) truth", (long long)x, (long long)y);
      series.push_back({name, wl, t, colours[k]});
      auto light = colours[k];
      for (int& c : light) c = 255 - (255 - c) / 3;  // the reconstruction in a lighter shade
      series.push_back({"  reconstruction", wl, p, light});
    }
    viz::write_line_plot(stem + "_spectra.png", "radiance spectra at three points (x, y)", "wavelength [nm]", series, false);
    // ColorChecker: recovered reflectance in each patch.
    const std::string layout = root + "/colorchecker_layout.json";
    if (std::filesystem::path(ls.file).stem() == "colorchecker" && std::filesystem::exists(layout)) {
      std::vector<std::string> names;
      const auto boxes = read_boxes(layout, &names);
      const torch::Tensor rec = patch_reflectances(hs, E, boxes);
      const torch::Tensor tru = patch_reflectances(sc.spectral * E.view({-1, 1, 1}), E, boxes);
      m.colorchecker_rmse = mean_patch_rmse(rec, tru);
      std::vector<std::string> files;
      for (size_t k = 0; k < boxes.size(); ++k) {
        const std::string f = out_dir + "/cc_" + std::to_string(k) + ".png";
        std::vector<double> t(tru[int64_t(k)].data_ptr<double>(), tru[int64_t(k)].data_ptr<double>() + tru.size(1));
        std::vector<double> r(rec[int64_t(k)].data_ptr<double>(), rec[int64_t(k)].data_ptr<double>() + rec.size(1));
        viz::write_line_plot(f, names[k], "nm", {{"truth", wl, t, {30, 30, 30}}, {"recovered", wl, r, {30, 30, 220}}}, false);
        files.push_back(f);
      }
      viz::write_montage(files, 6, 0.5, out_dir + "/colorchecker_spectra.png");
      cc_sum += m.colorchecker_rmse;
      ++cc_count;
    }
    res.scenes.push_back(m);
    progress.step();
  }
  progress.finish();
  auto& a = res.mean;
  a.file = "mean";
  const double n = double(res.scenes.size());
  for (const auto& m : res.scenes) {
    a.hs_psnr_db += m.hs_psnr_db / n, a.hs_ssim += m.hs_ssim / n, a.lum_psnr_db += m.lum_psnr_db / n;
    a.lum_ssim += m.lum_ssim / n, a.depth_rmse_m += m.depth_rmse_m / n, a.depth_mae_m += m.depth_mae_m / n;
    a.baseline_upsampling_hs_psnr_db += m.baseline_upsampling_hs_psnr_db / n;
    a.baseline_upsampling_hs_ssim += m.baseline_upsampling_hs_ssim / n;
    a.baseline_wiener_hs_psnr_db += m.baseline_wiener_hs_psnr_db / n;
    a.baseline_wiener_hs_ssim += m.baseline_wiener_hs_ssim / n;
  }
  if (sw_prior) {
    a.baseline_spectral_wiener_hs_psnr_db = a.baseline_spectral_wiener_hs_ssim = 0.0;
    for (const auto& m : res.scenes)
      a.baseline_spectral_wiener_hs_psnr_db += m.baseline_spectral_wiener_hs_psnr_db / n,
          a.baseline_spectral_wiener_hs_ssim += m.baseline_spectral_wiener_hs_ssim / n;
  }
  if (!res.scenes.empty() && std::isfinite(res.scenes.front().depth_known_spectral_wiener_hs_psnr_db)) {
    a.depth_known_spectral_wiener_hs_psnr_db = 0.0;
    for (const auto& m : res.scenes) a.depth_known_spectral_wiener_hs_psnr_db += m.depth_known_spectral_wiener_hs_psnr_db / n;
  }
  if (!res.scenes.empty() && std::isfinite(res.scenes.front().model_base_hs_psnr_db)) {
    a.model_base_hs_psnr_db = a.model_base_hs_ssim = 0.0;
    for (const auto& m : res.scenes) a.model_base_hs_psnr_db += m.model_base_hs_psnr_db / n, a.model_base_hs_ssim += m.model_base_hs_ssim / n;
  }
  a.layer_oracle_depth_rmse_m = a.layer_oracle_depth_mae_m = 0.0;
  a.baseline_defocus_depth_rmse_m = a.baseline_defocus_depth_mae_m = 0.0;
  for (const auto& m : res.scenes)
    a.baseline_defocus_depth_rmse_m += m.baseline_defocus_depth_rmse_m / n, a.baseline_defocus_depth_mae_m += m.baseline_defocus_depth_mae_m / n;
  if (sw_prior) {
    a.baseline_spectral_defocus_depth_rmse_m = a.baseline_spectral_defocus_depth_mae_m = 0.0;
    for (const auto& m : res.scenes)
      a.baseline_spectral_defocus_depth_rmse_m += m.baseline_spectral_defocus_depth_rmse_m / n,
          a.baseline_spectral_defocus_depth_mae_m += m.baseline_spectral_defocus_depth_mae_m / n;
  }
  for (const auto& m : res.scenes)
    a.layer_oracle_depth_rmse_m += m.layer_oracle_depth_rmse_m / n, a.layer_oracle_depth_mae_m += m.layer_oracle_depth_mae_m / n;
  if (!res.scenes.empty() && std::isfinite(res.scenes[0].network_depth_rmse_m)) {
    a.network_depth_rmse_m = a.network_depth_mae_m = a.fused_reader_depth_rmse_m = a.fused_reader_depth_mae_m = 0.0;
    for (const auto& m : res.scenes)
      a.network_depth_rmse_m += m.network_depth_rmse_m / n, a.network_depth_mae_m += m.network_depth_mae_m / n,
          a.fused_reader_depth_rmse_m += m.fused_reader_depth_rmse_m / n,
          a.fused_reader_depth_mae_m += m.fused_reader_depth_mae_m / n;
  }
  a.oracle_depth_rmse_m.assign(kOracleWindowsPx.size(), 0.0);
  for (const auto& m : res.scenes)
    for (size_t k = 0; k < kOracleWindowsPx.size(); ++k) a.oracle_depth_rmse_m[k] += m.oracle_depth_rmse_m[k] / n;
  a.depth_effective_resolution_px = effective_resolution_px(kOracleWindowsPx, a.oracle_depth_rmse_m, a.depth_rmse_m);
  if (constant_known) {
    a.baseline_constant_depth_rmse_m = a.baseline_constant_depth_mae_m = 0.0;
    for (const auto& m : res.scenes)
      a.baseline_constant_depth_rmse_m += m.baseline_constant_depth_rmse_m / n,
          a.baseline_constant_depth_mae_m += m.baseline_constant_depth_mae_m / n;
  }
  a.colorchecker_rmse = cc_count > 0 ? cc_sum / double(cc_count) : -1.0;
  // The interior's means over the scenes where each is reported (NaN when none
  // is): a metric over the scenes that have an interior, interior_fraction
  // over every scene with a valid pixel.
  a.interior_margin_px = interior_margin;
  for (const auto& m : res.scenes) a.interior_scenes += std::isfinite(m.interior_hs_psnr_db) ? 1 : 0;
  for (double SceneMetrics::*f :
       {&SceneMetrics::interior_fraction, &SceneMetrics::interior_hs_psnr_db, &SceneMetrics::interior_model_base_hs_psnr_db,
        &SceneMetrics::interior_baseline_upsampling_hs_psnr_db, &SceneMetrics::interior_baseline_spectral_wiener_hs_psnr_db,
        &SceneMetrics::interior_depth_rmse_m, &SceneMetrics::interior_baseline_constant_depth_rmse_m}) {
    double sum = 0.0;
    int64_t k = 0;
    for (const auto& m : res.scenes)
      if (std::isfinite(m.*f)) sum += m.*f, ++k;
    a.*f = k > 0 ? sum / double(k) : std::nan("");
  }
  viz::write_psf_atlas(out_dir + "/psf_atlas.png", imaging_psf,
                          psf.spec().wavelengths_m, psf.spec().depths_m);
  // metrics.json (docs/formats.md keys) and report.md.
  auto row = [](const SceneMetrics& m) {
    Json j{{"file", m.file}, {"hs_psnr_db", m.hs_psnr_db}, {"hs_ssim", m.hs_ssim}, {"lum_psnr_db", m.lum_psnr_db},
           {"lum_ssim", m.lum_ssim}, {"depth_rmse_m", m.depth_rmse_m}, {"depth_mae_m", m.depth_mae_m}};
    if (m.data_range > 0) j["psnr_data_range"] = m.data_range;
    if (m.colorchecker_rmse >= 0) j["colorchecker_reflectance_rmse"] = m.colorchecker_rmse;
    j["baseline_upsampling_hs_psnr_db"] = m.baseline_upsampling_hs_psnr_db;
    j["baseline_upsampling_hs_ssim"] = m.baseline_upsampling_hs_ssim;
    j["baseline_wiener_hs_psnr_db"] = m.baseline_wiener_hs_psnr_db;
    j["baseline_wiener_hs_ssim"] = m.baseline_wiener_hs_ssim;
    if (std::isfinite(m.baseline_spectral_wiener_hs_psnr_db)) {
      j["baseline_spectral_wiener_hs_psnr_db"] = m.baseline_spectral_wiener_hs_psnr_db;
      j["baseline_spectral_wiener_hs_ssim"] = m.baseline_spectral_wiener_hs_ssim;
    }
    if (std::isfinite(m.depth_known_spectral_wiener_hs_psnr_db))
      j["reference_depth_known_spectral_wiener_hs_psnr_db"] = m.depth_known_spectral_wiener_hs_psnr_db;
    if (std::isfinite(m.model_base_hs_psnr_db)) {
      j["model_base_hs_psnr_db"] = m.model_base_hs_psnr_db;
      j["model_base_hs_ssim"] = m.model_base_hs_ssim;
    }
    if (!m.illuminant_read.empty()) {
      j["illuminant_read"] = m.illuminant_read;
      j["illuminant_read_weight"] = m.illuminant_read_weight;
    }
    if (std::isfinite(m.baseline_constant_depth_rmse_m)) {
      j["baseline_constant_depth_rmse_m"] = m.baseline_constant_depth_rmse_m;
      j["baseline_constant_depth_mae_m"] = m.baseline_constant_depth_mae_m;
    }
    Json o = Json::object();
    for (size_t k = 0; k < m.oracle_depth_rmse_m.size(); ++k) o[std::to_string(kOracleWindowsPx[k])] = m.oracle_depth_rmse_m[k];
    j["reference_oracle_depth_rmse_m"] = o;
    j["reference_layer_oracle_depth_rmse_m"] = m.layer_oracle_depth_rmse_m;
    j["baseline_defocus_depth_rmse_m"] = m.baseline_defocus_depth_rmse_m;
    j["baseline_defocus_depth_mae_m"] = m.baseline_defocus_depth_mae_m;
    if (std::isfinite(m.baseline_spectral_defocus_depth_rmse_m)) {
      j["baseline_spectral_defocus_depth_rmse_m"] = m.baseline_spectral_defocus_depth_rmse_m;
      j["baseline_spectral_defocus_depth_mae_m"] = m.baseline_spectral_defocus_depth_mae_m;
    }
    j["reference_layer_oracle_depth_mae_m"] = m.layer_oracle_depth_mae_m;
    if (std::isfinite(m.network_depth_rmse_m)) {
      j["network_depth_rmse_m"] = m.network_depth_rmse_m;
      j["network_depth_mae_m"] = m.network_depth_mae_m;
      j["fused_reader_depth_rmse_m"] = m.fused_reader_depth_rmse_m;
      j["fused_reader_depth_mae_m"] = m.fused_reader_depth_mae_m;
    }
    j["interior_margin_px"] = m.interior_margin_px;
    if (std::isfinite(m.interior_fraction)) j["interior_fraction"] = m.interior_fraction;
    for (const auto& [key, v] : std::initializer_list<std::pair<const char*, double>>{
             {"interior_hs_psnr_db", m.interior_hs_psnr_db},
             {"interior_model_base_hs_psnr_db", m.interior_model_base_hs_psnr_db},
             {"interior_baseline_upsampling_hs_psnr_db", m.interior_baseline_upsampling_hs_psnr_db},
             {"interior_baseline_spectral_wiener_hs_psnr_db", m.interior_baseline_spectral_wiener_hs_psnr_db},
             {"interior_depth_rmse_m", m.interior_depth_rmse_m},
             {"interior_baseline_constant_depth_rmse_m", m.interior_baseline_constant_depth_rmse_m}})
      if (std::isfinite(v)) j[key] = v;
    if (!std::isnan(m.depth_effective_resolution_px))  // JSON has no infinity: coarser than every window is null
      j["depth_effective_resolution_px"] = std::isfinite(m.depth_effective_resolution_px) ? Json(m.depth_effective_resolution_px) : Json();
    return j;
  };
  const bool model_base_read = !model_map.defined() && std::isfinite(a.model_base_hs_psnr_db);  // the illuminant reader's base
  Json j = row(a);
  j.erase("file");
  j["split"] = split;
  j["interior_scenes"] = a.interior_scenes;
  if (constant_known) j["baseline_constant_depth_m"] = 1.0 / baseline_inv_depth;
  j["scenes"] = Json::array();
  for (const auto& m : res.scenes) j["scenes"].push_back(row(m));
  j["notes"] = "PSNR and SSIM data range: each scene's largest true radiance (luminance: its largest true Y); "
               "scene radiance = reflectance x " + cfg.sensor.illuminant + " (band means, max 1); SSIM per Wang et al. 2004 "
               "(11x11 Gaussian window, sigma 1.5) per band, averaged; every metric over the scene's valid pixels; "
               "baselines on the same pixels: the spectral-upsampling cube of the same sensor image (no network), the "
               "same upsampling of the mean over the depth layers of its Wiener deconvolutions (baseline_wiener_*, "
               "rho = model.preinverse_reg, no network)" +
               std::string(sw_prior ? ", the spectral Wiener cube (baseline_spectral_wiener_*: the LMMSE estimate of the "
                                      "cube from the image under the training radiance's spectral mean and covariance, "
                                      "every depth layer equally likely, no network)" : "") +
               std::string(model_map.defined() ? ", the network's residual base alone (model_base_*: its learned spectral "
                                                  "map on its residual base, no U-Net)"
                           : model_base_read ? ", the network's residual base alone (model_base_*: the spectral "
                                                         "Wiener cube under the posterior of the training illuminants the "
                                                         "illuminant reader gives for each scene, no U-Net; illuminant_read: "
                                                         "its most probable light per scene)"
                                                       : "") +
               " and one constant depth (the training split's median inverse depth); reference_oracle_depth_rmse_m: the "
               "resolution oracle (the true inverse depth averaged over a w x w box of valid pixels, w in px), a ruler "
               "for how fine the scenes' depth is, not a baseline; depth_effective_resolution_px: the box whose oracle "
               "scores the model's depth RMSE (mean over scenes); reference_layer_oracle_depth_rmse_m / _mae_m: the layer "
               "oracle (each valid pixel at the mean depth of its scene's valid pixels in the same rendering layer of "
               "optics.depths_m), what reading the optical cue perfectly and nothing else allows" +
               std::string(sw_prior ? "; reference_depth_known_spectral_wiener_hs_psnr_db: the spectral Wiener cube with "
                                      "each valid pixel's rendering layer known (that layer's LMMSE cube), what the depth "
                                      "adds to the linear cube, not a baseline" : "") +
               "; interior_*: the same metrics over the valid pixels at least interior_margin_px (the rendering margin, "
               "the PSF's reach) from every border, where every training patch's pixels lie, with the whole scene's "
               "data range (the mean: over the interior_scenes scenes that have such pixels; interior_fraction: their "
               "share of the valid pixels)";
  write_text_file(out_dir + "/metrics.json", j.dump(2) + "\n");
  std::string md = "# Evaluation (" + split + " split)\n\n" + j["notes"].get<std::string>() + ".\n\n" +
                   "| scene | HS PSNR [dB] | HS SSIM | Wiener baseline PSNR [dB] / SSIM | lum PSNR [dB] | lum SSIM | depth RMSE [m] | "
                   "depth MAE [m] | ColorChecker RMSE |\n"
                   "|---|---|---|---|---|---|---|---|---|\n";
  char buf[400];
  std::vector<SceneMetrics> all = res.scenes;
  all.push_back(a);
  auto depth_cell = [](double model, double base) {
    char c[64];
    if (std::isfinite(base)) std::snprintf(c, sizeof c, "%.4f (%.4f)", model, base);
    else std::snprintf(c, sizeof c, "%.4f", model);
    return std::string(c);
  };
  for (const auto& m : all) {
    std::snprintf(buf, sizeof buf, "| %s | %.2f (%.2f) | %.4f (%.4f) | %.2f / %.4f | %.2f | %.4f | %s | %s | %s |\n",
                  m.file == "mean" ? "**mean**" : m.file.c_str(), m.hs_psnr_db, m.baseline_upsampling_hs_psnr_db,
                  m.hs_ssim, m.baseline_upsampling_hs_ssim, m.baseline_wiener_hs_psnr_db, m.baseline_wiener_hs_ssim,
                  m.lum_psnr_db, m.lum_ssim,
                  depth_cell(m.depth_rmse_m, m.baseline_constant_depth_rmse_m).c_str(),
                  depth_cell(m.depth_mae_m, m.baseline_constant_depth_mae_m).c_str(),
                  m.colorchecker_rmse >= 0 ? c10::str(m.colorchecker_rmse).c_str() : "");
    md += buf;
  }
  md += "\nIn brackets: the baseline on the same pixels (HS: the upsampling cube of the sensor image alone; depth: ";
  md += constant_known ? "the constant " + c10::str(1.0 / baseline_inv_depth) + " m" : std::string("not known");
  md += "). A model that does not beat its baseline has learned nothing from the image.\n";
  if (std::isfinite(a.baseline_spectral_wiener_hs_psnr_db)) md += "\nMean over the scenes, " + spectral_wiener_summary(a) + ".\n";
  if (std::isfinite(a.model_base_hs_psnr_db)) {
    std::snprintf(buf, sizeof buf,
                  "\nThe network's residual base alone (%s, no U-Net), mean "
                  "over the scenes: HS PSNR %.2f dB, SSIM %.4f; the U-Net adds %+.2f dB to it.\n",
                  model_map.defined() ? "its learned spectral map on its residual base"
                                      : "the spectral Wiener cube under the light the illuminant reader read",
                  a.model_base_hs_psnr_db, a.model_base_hs_ssim, a.hs_psnr_db - a.model_base_hs_psnr_db);
    md += buf;
  }
  md += "\nThe resolution oracle (the true inverse depth averaged over a w × w box; what a depth sensor exact at w "
        "pixels and blind below would score), mean depth RMSE [m] over the scenes:\n\n| w [px] |";
  for (int64_t w : kOracleWindowsPx) md += " " + std::to_string(w) + " |";
  md += "\n|---|";
  for (size_t k = 0; k < kOracleWindowsPx.size(); ++k) md += "---|";
  md += "\n| oracle RMSE |";
  for (double r : a.oracle_depth_rmse_m) {
    std::snprintf(buf, sizeof buf, " %.4f |", r);
    md += buf;
  }
  std::snprintf(buf, sizeof buf,
                "\n\nThe model's depth RMSE (%.4f m) equals the oracle's at w = %s: depth structure finer than that is "
                "not recovered.\n",
                a.depth_rmse_m, effective_resolution_text(a.depth_effective_resolution_px).c_str());
  md += buf;
  std::snprintf(buf, sizeof buf,
                "\nThe layer oracle (each pixel at the mean depth of its scene's pixels in the same rendering layer: "
                "what reading the optical cue perfectly, and nothing else, allows with %zu layers), mean over the "
                "scenes: depth RMSE %.4f m, MAE %.4f m; the model is at %.2f x its RMSE.\n",
                psf.spec().depths_m.size(), a.layer_oracle_depth_rmse_m, a.layer_oracle_depth_mae_m,
                a.depth_rmse_m / std::max(1e-12, a.layer_oracle_depth_rmse_m));
  md += buf;
  std::snprintf(buf, sizeof buf,
                "\nThe classical depth-from-defocus reader (baseline_defocus_*: each pixel at the rendering layer of "
                "least local negative log-likelihood of the sensor image under a natural-texture model, "
                "model/defocus_likelihood.h, no learning), mean over the scenes: depth RMSE %.4f m, MAE %.4f m.\n",
                a.baseline_defocus_depth_rmse_m, a.baseline_defocus_depth_mae_m);
  md += buf;
  if (std::isfinite(a.baseline_spectral_defocus_depth_rmse_m)) {
    std::snprintf(buf, sizeof buf,
                  "\nThe same reader with the spectral Wiener baseline's spectral prior and band PSFs, colour and depth "
                  "read together (baseline_spectral_defocus_*, %lld-px box), mean over the scenes: depth RMSE %.4f m, "
                  "MAE %.4f m; the model is at %.2f x its RMSE.\n",
                  (long long)kSpectralDefocusWindowPx, a.baseline_spectral_defocus_depth_rmse_m,
                  a.baseline_spectral_defocus_depth_mae_m,
                  a.depth_rmse_m / std::max(1e-12, a.baseline_spectral_defocus_depth_rmse_m));
    md += buf;
  }
  if (std::isfinite(a.network_depth_rmse_m)) {
    std::snprintf(buf, sizeof buf,
                  "\nThe depth output fuses two readings (model.fuse_defocus_reader, model/depth_fusion.h), each alone "
                  "on the same pixels, mean over the scenes: the network's depth (network_depth_*) RMSE %.4f m, MAE "
                  "%.4f m; the spectral reader as fused (fused_reader_depth_*: its costs over a small box, filtered "
                  "under the cube) RMSE %.4f m, MAE %.4f m; fused: RMSE %.4f m, %.2f x the network's alone.\n",
                  a.network_depth_rmse_m, a.network_depth_mae_m, a.fused_reader_depth_rmse_m, a.fused_reader_depth_mae_m,
                  a.depth_rmse_m, a.depth_rmse_m / std::max(1e-12, a.network_depth_rmse_m));
    md += buf;
  }
  md += interior_summary(a) + "\n";
  md += "\nPictures: `<scene>_compare.png` (truth | reconstruction | |error| x4 | true depth | predicted depth), "
        "`<scene>_spectra.png`, `colorchecker_spectra.png`, `psf_atlas.png`.\n";
  write_text_file(out_dir + "/report.md", md);
  return res;
}

}  // namespace hsd::train
