// hsd_fabricate: a DOE height map in the forms a fab accepts (16-bit height
// map, K-level binary masks as PNG and GDSII; optics/lithography.h,
// optics/gdsii.h), a fabrication report, and with --tolerance the sensitivity
// of the design to the errors a fab makes (optics/fabrication_error.h,
// optics/fabrication_tolerance.h).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <torch/torch.h>                                    

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/sample_stats.h"
#include "common/log.h"
#include "common/tensor_io.h"
#include "common/text_format.h"
#include "optics/doe.h"
#include "optics/fabrication_error.h"
#include "optics/fabrication_tolerance.h"
#include "optics/fisher.h"
#include "optics/fisher_design.h"
#include "optics/gdsii.h"
#include "optics/lithography.h"
#include "optics/psf.h"
#include "optics/psf_mismatch.h"
#include "optics/psf_source.h"
#include "train/evaluator.h"
#include "train/trainer.h"
#include "viz/plot.h"
#include "usage/hsd_fabricate.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

// Images are encoded in memory and written whole (OpenCV picks the format by
// the extension, which the atomic writer's temporary name does not keep).
void write_image(const std::string& path, const cv::Mat& img) {
  std::vector<uchar> buf;
  const std::string ext = std::filesystem::path(path).extension().string();
  if (!cv::imencode(ext, img, buf)) throw std::runtime_error("OpenCV could not encode " + path);
  write_binary_file(path, std::vector<char>(buf.begin(), buf.end()));
}

cv::Mat to_mat_u16(const torch::Tensor& v) {  // [N, N] values in [0, 65535]
  const torch::Tensor t = v.round().clamp(0, 65535).to(torch::kInt32).contiguous();
  cv::Mat m(int(t.size(0)), int(t.size(1)), CV_32S, t.data_ptr<int32_t>());
  cv::Mat out;
  m.convertTo(out, CV_16U);
  return out;
}

cv::Mat to_mat_u8(const torch::Tensor& mask) {
  const torch::Tensor t = (mask.to(torch::kUInt8) * 255).contiguous();
  return cv::Mat(int(t.size(0)), int(t.size(1)), CV_8U, t.data_ptr<uint8_t>()).clone();
}

struct Inputs {
  torch::Tensor height;  // float64 [N, N], wrapped into [0, H)
  double max_height_m = 0;
  bool checkpoint = false;
};

Inputs read_doe(const Config& cfg, const optics::Material& material, const std::string& file) {
  Inputs in;
  const TensorDict d = load_tensor_dict(file);
  in.checkpoint = d.count("doe.raw") && d.count("step");
  const torch::Tensor h = optics::height_from_dict(d, file, cfg.optics.doe_samples, cfg.optics.doe_pitch_m);
  in.max_height_m = optics::doe_max_height_m(cfg.optics, material, h);
  in.height = torch::remainder(h, in.max_height_m);
  return in;
}

torch::Tensor simulate(const optics::PsfSimulator& sim, const torch::Tensor& height) {
  torch::NoGradGuard no_grad;
  return sim.compute(height).psf.to(torch::kFloat64);
}

struct PsfChange {
  double l1_mean = 0, l1_max = 0;  // relative L1 over bands and depths
  double shift_px = 0;             // mean centroid shift [px] (a decentre mostly moves the PSF)
};
PsfChange psf_change(const torch::Tensor& psf, const torch::Tensor& reference) {
  const optics::PsfMismatch m = optics::compare_psfs(psf, reference);
  return {m.rel_l1.mean().item<double>(), m.rel_l1.max().item<double>(),
          m.centroid_shift_px.pow(2).sum(-1).sqrt().mean().item<double>()};
}

// A picture of the fabrication: the design's heights, the quantised map, the
// masks, and the level histogram, in tiles of 256 px.
void write_fabrication_png(const std::string& path, const torch::Tensor& height, const optics::LevelMap& q,
                           const torch::Tensor& masks, double H) {
  const int T = 256;
  auto tile = [&](const torch::Tensor& v01, const std::string& label) {
    const torch::Tensor t = (v01.clamp(0, 1) * 255).round().to(torch::kUInt8).contiguous();
    cv::Mat m(int(t.size(0)), int(t.size(1)), CV_8U, t.data_ptr<uint8_t>());
    cv::Mat r;
    cv::resize(m, r, cv::Size(T, T), 0, 0, cv::INTER_NEAREST);
    cv::Mat c;
    cv::cvtColor(r, c, cv::COLOR_GRAY2BGR);
    cv::Mat out(T + 22, T, CV_8UC3, cv::Scalar(255, 255, 255));
    c.copyTo(out(cv::Rect(0, 22, T, T)));
    cv::putText(out, label, {4, 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1, cv::LINE_AA);
    return out;
  };
  std::vector<cv::Mat> tiles{tile(height / H, "design height (0..H)"),
                             tile(optics::level_heights(q) / H, std::to_string(q.levels) + " levels")};
  for (int64_t k = 0; k < masks.size(0); ++k)
    tiles.push_back(tile(masks[k].to(torch::kFloat64), "mask " + std::to_string(k) + " (layer " + std::to_string(k + 1) + ")"));
  {  // histogram
    cv::Mat h(T + 22, T, CV_8UC3, cv::Scalar(255, 255, 255));
    const auto counts = optics::level_histogram(q);
    const double top = double(*std::max_element(counts.begin(), counts.end()));
    const double w = double(T - 8) / double(counts.size());
    for (size_t k = 0; k < counts.size(); ++k) {
      const int bh = int(std::round(double(T - 30) * double(counts[k]) / std::max(top, 1.0)));
      cv::rectangle(h, cv::Rect(int(4 + w * double(k)), T + 22 - 4 - bh, std::max(1, int(w) - 1), bh), {150, 90, 40}, cv::FILLED);
    }
    cv::putText(h, "cells per level", {4, 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45, {0, 0, 0}, 1, cv::LINE_AA);
    tiles.push_back(h);
  }
  const int cols = 4, rows = int((tiles.size() + cols - 1) / cols);
  cv::Mat canvas(rows * (T + 26), cols * (T + 4), CV_8UC3, cv::Scalar(255, 255, 255));
  for (size_t i = 0; i < tiles.size(); ++i)
    tiles[i].copyTo(canvas(cv::Rect(int(i % cols) * (T + 4), int(i / cols) * (T + 26), tiles[i].cols, tiles[i].rows)));
  write_image(path, canvas);
}

struct Export {
  optics::LevelMap q;
  Json report;
  std::string markdown;
};

Export export_doe(const AppArgs& args, const Config& cfg, const optics::Material& material, const Inputs& in,
                  const std::string& doe_file) {
  const auto& F = cfg.fabrication;
  const std::string& out = args.out_dir;
  const double pitch = cfg.optics.doe_pitch_m, H = in.max_height_m;
  const int64_t N = cfg.optics.doe_samples, K = F.levels;
  Export ex;
  ex.q = optics::quantize_to_levels(in.height, H, K);
  const torch::Tensor masks = optics::level_masks(ex.q);
  const int64_t m = masks.size(0);
  // The masks must make the quantised map exactly (optics/lithography.h).
  if (!torch::equal(optics::height_from_masks(masks, ex.q.step_m), optics::level_heights(ex.q)))
    throw std::logic_error("the level masks do not reconstruct the quantised height map");

  // 16-bit height map: 0 = no material, 65535 = H (the design, for a grayscale process).
  const cv::Mat hm = to_mat_u16(in.height / H * 65535.0);
  write_image(out + "/height_map.png", hm);
  write_image(out + "/height_map.tif", hm);
  Json side;
  side["_note"] = "hsd_fabricate: height_map.png/.tif are 16-bit grayscale, value v <-> height v / 65535 * max_height_m "
                  "(0 = no material). Row r, column c is DOE cell [r, c] at x = (c - (N-1)/2) * pitch_m, "
                  "y = (r - (N-1)/2) * pitch_m: the DOE seen from the scene, looking along +z towards the sensor "
                  "(x right, y down). masks.gds has y up: the same DOE seen from the sensor side.";
  side["max_height_m"] = H;
  side["pitch_m"] = pitch;
  side["samples"] = N;
  side["levels"] = K;
  side["level_step_m"] = ex.q.step_m;
  side["material"] = cfg.optics.material;
  side["refractive_index_at_design"] = material.index(cfg.optics.doe.design_wavelength_m);
  side["design_wavelength_m"] = cfg.optics.doe.design_wavelength_m;
  side["aperture_diameter_m"] = cfg.optics.aperture_diameter_m;
  side["orientation"] = "row r = DOE row r (y grows downwards in the picture), column c = DOE column c (x grows rightwards); seen from the scene side";
  side["source"] = doe_file;
  write_text_file(out + "/height_map.json", side.dump(2) + "\n");

  // Masks: PNG and GDSII.
  std::vector<optics::GdsLayer> layers;
  Json mask_rows = Json::array();
  double min_feature = std::numeric_limits<double>::infinity();
  int64_t below = 0;
  const double min_cells = F.min_feature_m / pitch;
  for (int64_t k = 0; k < m; ++k) {
    write_image(out + "/mask_" + std::to_string(k) + ".png", to_mat_u8(masks[k]));
    optics::GdsLayer l;
    l.layer = k + 1;
    l.rects = optics::mask_rectangles(masks[k]);
    const optics::MaskFeatures f = optics::mask_features(masks[k], min_cells);
    for (int64_t c : {f.min_line_cells, f.min_space_cells})
      if (c > 0) min_feature = std::min(min_feature, double(c) * pitch);
    below += f.lines_below + f.spaces_below;
    mask_rows.push_back({{"mask", k},
                         {"gds_layer", k + 1},
                         {"etch_depth_m", double(int64_t(1) << k) * ex.q.step_m},
                         {"covered_fraction", f.covered_fraction},
                         {"area_m2", f.covered_fraction * double(N * N) * pitch * pitch},
                         {"rectangles", int64_t(l.rects.size())},
                         {"min_line_m", f.min_line_cells > 0 ? Json(double(f.min_line_cells) * pitch) : Json(nullptr)},
                         {"min_space_m", f.min_space_cells > 0 ? Json(double(f.min_space_cells) * pitch) : Json(nullptr)},
                         {"lines_below_min", f.lines_below},
                         {"spaces_below_min", f.spaces_below}});
    layers.push_back(std::move(l));
  }
  write_binary_file(out + "/masks.gds", optics::gdsii_bytes(layers, N, pitch, F.cell_name, "HSD"));

  // Quantisation: height error and the PSF change it makes.
  const double qrms = optics::quantisation_rms_m(in.height, ex.q, H);
  const double eff = std::pow(std::sin(M_PI / double(K)) / (M_PI / double(K)), 2);
  const optics::PsfSimulator sim(optics::make_psf_spec(cfg.optics, material, torch::kCPU));
  log::info("PSFs of the design and of its " + std::to_string(K) + "-level map");
  const torch::Tensor psf_design = simulate(sim, in.height), psf_q = simulate(sim, optics::level_heights(ex.q));
  const PsfChange qc = psf_change(psf_q, psf_design);
  const double q_l1_mean = qc.l1_mean, q_l1_max = qc.l1_max;
  write_fabrication_png(out + "/fabrication.png", in.height, ex.q, masks, H);

  Json& j = ex.report;
  j["levels"] = K;
  j["masks"] = m;
  j["level_step_m"] = ex.q.step_m;
  j["max_height_m"] = H;
  j["pitch_m"] = pitch;
  j["min_feature_m"] = std::isfinite(min_feature) ? Json(min_feature) : Json(nullptr);
  j["min_feature_required_m"] = F.min_feature_m;
  j["features_below_min"] = below;
  j["quantisation_rms_m"] = qrms;
  j["quantisation_rms_rad"] = 2.0 * M_PI * qrms / H;
  j["first_order_efficiency_sinc2"] = eff;
  j["quantisation_psf_rel_l1_mean"] = q_l1_mean;
  j["quantisation_psf_rel_l1_max"] = q_l1_max;
  j["height_histogram"] = optics::level_histogram(ex.q);
  j["mask_report"] = mask_rows;
  j["gds"] = {{"file", "masks.gds"}, {"cell", F.cell_name}, {"user_unit_m", 1e-6}, {"database_unit_m", 1e-9}};

  std::string& md = ex.markdown;
  md += "# Fabrication report\n\n";
  md += "DOE `" + doe_file + "`: " + std::to_string(N) + "x" + std::to_string(N) + " cells of " + format_g(pitch * 1e6) +
        " um, heights wrapped into [0, " + format_g(H * 1e9) + " nm) (" + cfg.optics.material + "), " + std::to_string(K) +
        " levels of " + format_g(ex.q.step_m * 1e9) + " nm made by " + std::to_string(m) + " binary masks.\n\n";
  md += "| quantity | value |\n|---|---|\n";
  md += "| quantisation error (RMS, phase-equivalent) | " + format_g(qrms * 1e9) + " nm (" + format_g(2.0 * M_PI * qrms / H, 3) + " rad) |\n";
  md += "| first-order efficiency of " + std::to_string(K) + " levels, sinc^2(1/K) | " + format_g(eff, 4) + " |\n";
  md += "| PSF change from quantisation, rel. L1 mean / max | " + format_g(q_l1_mean, 3) + " / " + format_g(q_l1_max, 3) + " |\n";
  md += "| smallest feature found | " + (std::isfinite(min_feature) ? format_g(min_feature * 1e6) + " um" : std::string("none")) + " |\n";
  md += "| process minimum (fabrication.min_feature_m) | " + format_g(F.min_feature_m * 1e6) + " um |\n";
  md += "| features below the minimum | " + std::to_string(below) + (below > 0 ? " **(flagged)**" : "") + " |\n\n";
  md += "| mask | GDS layer | etch depth [nm] | covered | rectangles | min line [um] | min space [um] | lines / spaces below min |\n";
  md += "|---|---|---|---|---|---|---|---|\n";
  for (const Json& r : mask_rows) {
    auto um = [&](const Json& v) { return v.is_null() ? std::string("-") : format_g(v.get<double>() * 1e6); };
    md += "| " + std::to_string(r["mask"].get<int64_t>()) + " | " + std::to_string(r["gds_layer"].get<int64_t>()) + " | " +
          format_g(r["etch_depth_m"].get<double>() * 1e9) + " | " + format_g(100.0 * r["covered_fraction"].get<double>(), 3) + " % | " +
          std::to_string(r["rectangles"].get<int64_t>()) + " | " + um(r["min_line_m"]) + " | " + um(r["min_space_m"]) + " | " +
          std::to_string(r["lines_below_min"].get<int64_t>()) + " / " + std::to_string(r["spaces_below_min"].get<int64_t>()) + " |\n";
  }
  md += "\n![fabrication](fabrication.png)\n";
  return ex;
}

// What every fabricated surface of the tolerance sweep is measured with: the
// simulator on the refined grid, the point-source CRLB, and the checkpoint's
// network on the test split (when the DOE is a checkpoint and its dataset is
// there), each against the reference: the K-level design without error.
struct ToleranceBench {
  ToleranceBench(const AppArgs& args, const Config& cfg, const optics::Material& material, const Inputs& in,
                 const std::string& doe_file, const optics::LevelMap& q)
      : cfg(cfg),
        material(material),
        s(cfg.fabrication.tolerance.subsamples),
        spec(optics::make_psf_spec(refined(cfg.optics, s), material, torch::kCPU)),
        sim(spec),
        geometry(optics::make_fisher_geometry(spec, cfg.fisher.window_px, cfg.fisher.pixel_nodes)),
        fisher(optics::fisher_settings(cfg)),
        hq(optics::level_heights(q)),
        process{cfg.optics.doe_pitch_m, s, in.max_height_m, cfg.fabrication.levels, 0.0},
        scratch(args.out_dir + "/.tolerance_eval") {
    if (cfg.fabrication.tolerance.network && in.checkpoint) {
      if (std::filesystem::exists(cfg.data.root + "/manifest.json")) {
        trainer = std::make_unique<train::Trainer>(cfg);
        trainer->load_checkpoint(doe_file);
      } else {
        log::warn("no dataset at " + cfg.data.root + " (data.root): the sweep reports PSFs and CRLBs only");
      }
    }
    ref_surface = optics::fabricated_surface(hq, {}, process, cfg.seed);
    ref_psf = psf(ref_surface);
    ref_crlb = crlb(ref_surface);
    ref_net = network(ref_psf);
  }

  bool with_network() const { return trainer != nullptr; }
  torch::Tensor psf(const torch::Tensor& surface) const { return simulate(sim, surface); }
  double crlb(const torch::Tensor& surface) const {
    return optics::crlb_report(geometry, material, surface, fisher).aggregate.item<double>();
  }
  // (HS PSNR [dB], depth RMSE [m]) on the test split with the scenes imaged
  // through `psf` (undefined: the design's own PSFs, as trained); NaNs without
  // a network. The pre-inversion keeps the design's PSFs (with
  // fabrication.tolerance.calibrated: the surface's, as a calibrated camera).
  std::pair<double, double> network(const torch::Tensor& psf) const {
    if (!trainer) return {std::nan(""), std::nan("")};
    const train::EvalResult r = train::evaluate(*trainer, cfg, "test", scratch,
                                                psf.defined() ? optics::fixed_psf_provider(psf.to(torch::kFloat32)) : nullptr,
                                                cfg.fabrication.tolerance.calibrated);
    std::filesystem::remove_all(scratch);
    return {r.mean.hs_psnr_db, r.mean.depth_rmse_m};
  }

  static OpticsConfig refined(OpticsConfig o, int64_t s) {
    o.doe_samples *= s;
    o.doe_pitch_m /= double(s);
    return o;
  }

  const Config& cfg;
  const optics::Material& material;
  const int64_t s;  // sub-cells per DOE cell and axis
  const optics::PsfSpec spec;
  const optics::PsfSimulator sim;
  const optics::FisherGeometry geometry;
  const optics::FisherSettings fisher;
  const torch::Tensor hq;              // the K-level heights on the DOE grid [N, N] m
  optics::FabricationProcess process;  // how the refined surface is made from them
  const std::string scratch;          // hsd_eval's outputs for one surface, removed after it
  std::unique_ptr<train::Trainer> trainer;
  torch::Tensor ref_surface, ref_psf;  // the design without error: surface [sN, sN] m, PSFs
  double ref_crlb = 0;
  std::pair<double, double> ref_net;  // its (HS PSNR, depth RMSE); NaNs without a network
};

// One error swept alone over its sizes: a markdown row per size, its JSON row,
// and its plots (paths appended to `plots`).
Json sweep_one(const optics::ToleranceSweep& sw, const ToleranceBench& b, const Config& cfg, const std::string& out_dir,
               std::string& md, std::vector<std::string>& plots, log::Progress& progress) {
  const bool net_on = b.with_network();
  Json r;
  r["kind"] = sw.name;
  r["size_label"] = sw.size_label;
  r["sizes"] = sw.sizes;
  std::vector<double> l1_mean, l1_max, shift, cr, psnr, rmse;
  for (double size : sw.sizes) {
    // Size 0 is the reference surface itself (fabricated_surface is exact there): its row is the reference's.
    const bool zero = size == 0.0;
    const torch::Tensor surface =
        zero ? b.ref_surface
             : optics::fabricated_surface(b.hq, optics::tolerance_error(sw, size, cfg.fabrication.tolerance), b.process, cfg.seed + 1000);
    const torch::Tensor psf = zero ? b.ref_psf : b.psf(surface);
    const PsfChange c = zero ? PsfChange{} : psf_change(psf, b.ref_psf);
    l1_mean.push_back(c.l1_mean), l1_max.push_back(c.l1_max), shift.push_back(c.shift_px);
    cr.push_back(zero ? b.ref_crlb : b.crlb(surface));
    const auto net = zero ? b.ref_net : b.network(psf);
    psnr.push_back(net.first), rmse.push_back(net.second);
    md += "| " + sw.size_label + " | " + format_g(size * sw.unit_scale, 3) + " | " + format_g(c.l1_mean, 3) + " | " +
          format_g(c.l1_max, 3) + " | " + format_g(c.shift_px, 3) + " | " + format_g(cr.back(), 3) + " | " +
          (net_on ? format_g(net.first) : std::string("-")) + " | " + (net_on ? format_g(net.second, 3) : std::string("-")) + " |\n";
    progress.step();
  }
  r["psf_rel_l1_mean"] = l1_mean, r["psf_rel_l1_max"] = l1_max, r["psf_centroid_shift_px"] = shift, r["crlb_aggregate"] = cr;
  if (net_on) r["hs_psnr_db"] = psnr, r["depth_rmse_m"] = rmse;
  std::vector<double> x;
  for (double v : sw.sizes) x.push_back(v * sw.unit_scale);
  auto plot = [&](const std::string& name, const std::string& title, const std::vector<double>& y) {
    const std::string f = out_dir + "/.tol_" + sw.name + "_" + name + ".png";
    viz::write_line_plot(f, title, sw.size_label, {{title, x, y, {150, 60, 20}}}, false);
    plots.push_back(f);
  };
  plot("l1", "PSF change (rel. L1, mean)", l1_mean);
  plot("crlb", "CRLB (" + choice_name(cfg.fisher.aggregate) + ")", cr);
  if (net_on) plot("psnr", "HS PSNR [dB]", psnr), plot("rmse", "depth RMSE [m]", rmse);
  return r;
}

// fabrication.tolerance.draws: the errors together, drawn as training draws
// them (optics::draw_fabrication_error) from draw_scales; draw d is seeded by
// d alone, so every DOE meets the same surfaces' errors. Per draw and as mean
// ± SD: PSF change, CRLB and the network's loss against the reference.
Json random_draws(const FabricationToleranceConfig& T, const ToleranceBench& b, std::string& md, log::Progress& progress) {
  const auto& E = T.draw_scales;
  const bool net_on = b.with_network();
  optics::FabricationProcess process = b.process;
  md += "\n## Random draws\n\n" + std::to_string(T.draws) + " draws of the errors together (as `train.fabrication_noise` draws them): etch-depth error ~ N(0, " +
        format_g(100 * E.height_scale_error) + " %), roughness " + format_g(E.roughness_rms_m * 1e9) + " nm RMS over " +
        format_g(E.roughness_correlation_m * 1e6) + " um, edge blur sigma ~ U(0, " + format_g(E.edge_blur_m * 1e6) + " um), " +
        (E.decentre_m > 0 ? "decentre ~ U(0, " + format_g(E.decentre_m * 1e6) + " um)" : std::string("no decentre")) + ". Draw d is seeded by d alone: every DOE meets the same draws. Losses against the reference (no error).\n\n";
  md += "| draw | etch [%] | edge blur [um] | decentre [um] | PSF rel. L1 mean | CRLB | HS PSNR loss [dB] | depth RMSE loss [m] |\n"
        "|---|---|---|---|---|---|---|---|\n";
  Json rows = Json::array();
  std::vector<double> l1, cr, dpsnr, drmse;
  for (int64_t d = 0; d < T.draws; ++d) {
    std::mt19937_64 rng(0xD4A3'0000ull + uint64_t(d));
    double angle = 0;
    const FabricationErrorConfig e = optics::draw_fabrication_error(E, rng, &angle);
    process.decentre_angle_rad = angle;
    const torch::Tensor surface = optics::fabricated_surface(b.hq, e, process, rng());
    const torch::Tensor psf = b.psf(surface);
    const PsfChange c = psf_change(psf, b.ref_psf);
    const auto net = b.network(psf);
    l1.push_back(c.l1_mean), cr.push_back(b.crlb(surface));
    dpsnr.push_back(b.ref_net.first - net.first), drmse.push_back(net.second - b.ref_net.second);
    rows.push_back({{"height_scale_error", e.height_scale_error}, {"edge_blur_m", e.edge_blur_m}, {"decentre_m", e.decentre_m},
                    {"psf_rel_l1_mean", c.l1_mean}, {"crlb_aggregate", cr.back()}, {"hs_psnr_db", net.first}, {"depth_rmse_m", net.second}});
    md += "| " + std::to_string(d) + " | " + format_g(100 * e.height_scale_error, 3) + " | " + format_g(e.edge_blur_m * 1e6, 3) + " | " +
          format_g(e.decentre_m * 1e6, 3) + " | " + format_g(c.l1_mean, 3) + " | " + format_g(cr.back(), 3) + " | " +
          (net_on ? format("%+.3f", dpsnr.back()) : std::string("-")) + " | " +
          (net_on ? format("%+.4f", drmse.back()) : std::string("-")) + " |\n";
    progress.step();
  }
  const SampleStats L1 = sample_stats(l1), CR = sample_stats(cr), P = sample_stats(dpsnr), R = sample_stats(drmse);
  md += "| mean ± SD | | | | " + format_g(L1.mean, 3) + " ± " + format_g(L1.sd, 2) + " | " + format_g(CR.mean, 3) + " ± " + format_g(CR.sd, 2) + " | " +
        (net_on ? format("%+.3f ± %.3f", P.mean, P.sd) : std::string("-")) + " | " +
        (net_on ? format("%+.4f ± %.4f", R.mean, R.sd) : std::string("-")) + " |\n";
  Json j{{"scales", {{"height_scale_error", E.height_scale_error}, {"roughness_rms_m", E.roughness_rms_m},
                     {"roughness_correlation_m", E.roughness_correlation_m}, {"edge_blur_m", E.edge_blur_m}, {"decentre_m", E.decentre_m}}},
         {"rows", rows}, {"psf_rel_l1_mean", {{"mean", L1.mean}, {"sd", L1.sd}}}, {"crlb_aggregate", {{"mean", CR.mean}, {"sd", CR.sd}}}};
  if (net_on)
    j["hs_psnr_loss_db"] = {{"mean", P.mean}, {"sd", P.sd}}, j["depth_rmse_loss_m"] = {{"mean", R.mean}, {"sd", R.sd}};
  return j;
}

// The tolerance sweep; returns its JSON and appends its markdown.
Json tolerance(const AppArgs& args, const Config& cfg, const optics::Material& material, const Inputs& in,
               const std::string& doe_file, const optics::LevelMap& q, std::string& md) {
  const auto& T = cfg.fabrication.tolerance;
  const auto sweeps = optics::tolerance_sweeps(T);
  int64_t total = T.draws;
  for (const auto& sw : sweeps) total += int64_t(sw.sizes.size());
  log::info("tolerance sweep: " + std::to_string(total) + " fabricated surfaces on " + std::to_string(cfg.optics.doe_samples * T.subsamples) +
            "^2 sub-cells (" + std::to_string(T.subsamples) + "x" + std::to_string(T.subsamples) + " per DOE cell)" +
            (T.network && in.checkpoint ? ", each evaluated by the network" : ""));
  const auto t0 = std::chrono::steady_clock::now();
  const ToleranceBench b(args, cfg, material, in, doe_file, q);
  const auto design_net = b.network({});  // through the design's own PSFs (as trained)
  const int64_t K = cfg.fabrication.levels;
  Json j;
  j["subsamples"] = b.s;
  j["levels"] = K;
  j["reference"] = {{"crlb_aggregate", b.ref_crlb}, {"hs_psnr_db", b.ref_net.first}, {"depth_rmse_m", b.ref_net.second}};
  j["design"] = {{"hs_psnr_db", design_net.first}, {"depth_rmse_m", design_net.second}};
  j["crlb_aggregate_name"] = choice_name(cfg.fisher.aggregate);
  j["calibrated"] = T.calibrated;
  md += "\n# Tolerance\n\nEach error alone, against the " + std::to_string(K) + "-level design without error (CRLB " +
        format_g(b.ref_crlb, 3) + " layers/bands, " + choice_name(cfg.fisher.aggregate) + ")";
  if (b.with_network())
    md += "; the network through the design's own PSFs: HS PSNR " + format_g(design_net.first) + " dB, depth RMSE " +
          format_g(design_net.second, 3) + " m; through the " + std::to_string(K) + "-level map: " + format_g(b.ref_net.first) +
          " dB, " + format_g(b.ref_net.second, 3) + " m (test split)" +
          (T.calibrated ? "; calibrated: the network's pre-inversion, its spectral Wiener filter and the Wiener baselines "
                          "use each surface's own PSFs"
                        : "");
  md += ". Surfaces on " + std::to_string(b.s) + "x" + std::to_string(b.s) + " sub-cells per DOE cell.\n\n";
  md += "| error | size | PSF rel. L1 mean | max | centroid shift [px] | CRLB | HS PSNR [dB] | depth RMSE [m] |\n"
        "|---|---|---|---|---|---|---|---|\n";
  log::Progress progress("tolerance", long(total));
  Json rows = Json::array();
  std::vector<std::string> plots;
  for (const auto& sw : sweeps) rows.push_back(sweep_one(sw, b, cfg, args.out_dir, md, plots, progress));
  if (T.draws > 0) j["draws"] = random_draws(T, b, md, progress);
  progress.finish();
  j["sweeps"] = rows;
  j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  viz::write_montage(plots, b.with_network() ? 4 : 2, 1.0, args.out_dir + "/tolerance.png");
  md += "\n![tolerance](tolerance.png)\n";
  return j;
}

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  if (!args.has("--doe")) input_error("--doe", "required: a training checkpoint or a height-map file");
  const std::string doe_file = args.option("--doe", "");
  const auto material = optics::Material::load(cfg.optics.material);
  const Inputs in = read_doe(cfg, material, doe_file);
  const bool sweep = args.has("--tolerance");
  const std::string& out = args.out_dir;
  const int64_t m = optics::level_mask_count(cfg.fabrication.levels);
  std::vector<std::string> outputs{out + "/height_map.png", out + "/height_map.tif", out + "/height_map.json",
                                   out + "/masks.gds", out + "/fabrication.json", out + "/fabrication.md",
                                   out + "/fabrication.png"};
  for (int64_t k = 0; k < m; ++k) outputs.push_back(out + "/mask_" + std::to_string(k) + ".png");
  if (sweep)
    for (const char* f : {"/tolerance.json", "/tolerance.md", "/tolerance.png"}) outputs.push_back(out + f);
  {  // the pitch must be a whole number of GDSII database units (1 nm)
    const double nm = cfg.optics.doe_pitch_m * 1e9;
    if (std::fabs(nm - std::round(nm)) > 1e-6 * nm)
      input_error("config key optics.doe_pitch_m", "must be a whole number of nanometres for GDSII, got " + c10::str(cfg.optics.doe_pitch_m));
  }
  setup_threads(cfg.threads);
  make_dirs(out);
  check_output_paths(outputs);
  log::info("DOE " + doe_file + (in.checkpoint ? " (checkpoint)" : " (height map)") + ": " +
            std::to_string(cfg.optics.doe_samples) + "^2 cells, period " + format_g(in.max_height_m * 1e9) + " nm, " +
            std::to_string(cfg.fabrication.levels) + " levels");
  Export ex = export_doe(args, cfg, material, in, doe_file);
  if (sweep) {
    Json t = tolerance(args, cfg, material, in, doe_file, ex.q, ex.markdown);
    write_text_file(out + "/tolerance.json", t.dump(2) + "\n");
  }
  write_text_file(out + "/fabrication.json", ex.report.dump(2) + "\n");
  write_text_file(out + "/fabrication.md", ex.markdown);
  if (sweep) write_text_file(out + "/tolerance.md", ex.markdown.substr(ex.markdown.find("\n# Tolerance") + 1));
  write_resolved_config(cfg, out);
  const int64_t below = ex.report["features_below_min"].get<int64_t>();
  log::info("levels " + std::to_string(cfg.fabrication.levels) + ", quantisation RMS " +
            format_g(ex.report["quantisation_rms_m"].get<double>() * 1e9, 3) + " nm, PSF change " +
            format_g(ex.report["quantisation_psf_rel_l1_mean"].get<double>(), 3) + "; smallest feature " +
            (ex.report["min_feature_m"].is_null() ? std::string("none") : format_g(ex.report["min_feature_m"].get<double>() * 1e6, 3) + " um") +
            (below > 0 ? ", " + std::to_string(below) + " features below fabrication.min_feature_m (flagged in fabrication.md)" : ""));
  log::info("wrote height_map.{png,tif,json}, mask_0.." + std::to_string(m - 1) + ".png, masks.gds, fabrication.{json,md,png}" +
            std::string(sweep ? ", tolerance.{json,md,png}" : "") + " to " + out);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_fabricate", kUsage, {"--doe"}, {"--tolerance"}, true, true};
  return run_app(spec, argc, argv, run);
}
