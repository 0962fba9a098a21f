#include "data/realism_stats.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include <opencv2/imgproc.hpp>
#include <torch/torch.h>

#include "data/depth_structure.h"

#include "common/error.h"
#include "data/preview.h"
#include "optics/spectrum.h"

namespace hsd::data {

namespace {
const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
using torch::indexing::None;
using torch::indexing::Slice;

// At most ~50k rows, evenly strided (deterministic), for the PCA and the regression.
torch::Tensor subsample_rows(const torch::Tensor& x, int64_t max_rows = 50000) {
  if (x.size(0) <= max_rows) return x;
  const int64_t stride = (x.size(0) + max_rows - 1) / max_rows;
  return x.index({Slice(None, None, stride)});
}
}  // namespace

double textured_fraction(const torch::Tensor& lum_in, const torch::Tensor& valid_in, double radius_px,
                         double rel_threshold) {
  const torch::Tensor lum = lum_in.to(torch::kFloat64).contiguous();
  const torch::Tensor valid = valid_in.to(torch::kBool).contiguous();
  const int64_t H = lum.size(0), W = lum.size(1);
  const int64_t n_valid = valid.sum().item<int64_t>();
  if (n_valid == 0) return 0.0;
  const double thr = rel_threshold * lum.masked_select(valid).mean().item<double>();
  // Forward differences between valid neighbours; both pixels of a strong pair are edges.
  torch::Tensor edge = torch::zeros({H, W}, torch::kBool);
  {
    const torch::Tensor d = (lum.index({Slice(), Slice(1, None)}) - lum.index({Slice(), Slice(None, -1)})).abs();
    const torch::Tensor ok = valid.index({Slice(), Slice(1, None)}) & valid.index({Slice(), Slice(None, -1)});
    const torch::Tensor strong = (d > thr) & ok;
    edge.index({Slice(), Slice(1, None)}) |= strong;
    edge.index({Slice(), Slice(None, -1)}) |= strong;
  }
  {
    const torch::Tensor d = (lum.index({Slice(1, None)}) - lum.index({Slice(None, -1)})).abs();
    const torch::Tensor ok = valid.index({Slice(1, None)}) & valid.index({Slice(None, -1)});
    const torch::Tensor strong = (d > thr) & ok;
    edge.index({Slice(1, None)}) |= strong;
    edge.index({Slice(None, -1)}) |= strong;
  }
  if (!edge.any().item<bool>()) return 0.0;
  // Distance of every pixel to the nearest edge pixel (exact Euclidean transform).
  cv::Mat not_edge(int(H), int(W), CV_8U);
  const torch::Tensor ne = (~edge).to(torch::kUInt8).mul(255).contiguous();
  std::memcpy(not_edge.data, ne.data_ptr<uint8_t>(), size_t(H * W));
  cv::Mat dist;
  cv::distanceTransform(not_edge, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  const torch::Tensor d = torch::from_blob(dist.data, {H, W}, torch::kFloat32).clone();
  const torch::Tensor near = (d <= float(radius_px)) & valid;
  return double(near.sum().item<int64_t>()) / double(n_valid);
}

double power_spectrum_slope(const torch::Tensor& lum_in, const torch::Tensor& valid_in) {
  torch::Tensor lum = lum_in.to(torch::kFloat64);
  const int64_t H = lum.size(0), W = lum.size(1);
  if (H < 16 || W < 16) throw InputError("power-spectrum slope: the image must be at least 16 x 16 pixels");
  if (valid_in.defined()) {
    const torch::Tensor v = valid_in.to(torch::kBool);
    const double m = v.any().item<bool>() ? lum.masked_select(v).mean().item<double>() : 0.0;
    lum = torch::where(v, lum, torch::full_like(lum, m));
  }
  lum = lum - lum.mean();
  const torch::Tensor wy = torch::hann_window(H, /*periodic=*/false, f64), wx = torch::hann_window(W, false, f64);
  lum = lum * wy.view({H, 1}) * wx.view({1, W});
  const torch::Tensor P = torch::fft::fft2(lum).abs().pow(2);
  const torch::Tensor fy = torch::fft::fftfreq(H, 1.0, f64).view({H, 1}), fx = torch::fft::fftfreq(W, 1.0, f64).view({1, W});
  const torch::Tensor f = (fy * fy + fx * fx).sqrt();
  const double f_lo = 4.0 / double(std::min(H, W)), f_hi = 0.4;
  const int bins = 16;
  std::vector<double> xs, ys;
  const double l0 = std::log(f_lo), l1 = std::log(f_hi);
  const torch::Tensor lf = f.clamp_min(1e-12).log();
  for (int b = 0; b < bins; ++b) {
    const double a = l0 + (l1 - l0) * b / bins, c = l0 + (l1 - l0) * (b + 1) / bins;
    const torch::Tensor sel = (lf >= a) & (lf < c);
    const int64_t n = sel.sum().item<int64_t>();
    if (n == 0) continue;
    const double p = P.masked_select(sel).mean().item<double>();
    if (!(p > 0)) continue;
    xs.push_back(lf.masked_select(sel).mean().item<double>());
    ys.push_back(std::log(p));
  }
  if (xs.size() < 3) throw InputError("power-spectrum slope: too few frequency bins");
  double mx = 0, my = 0;
  for (size_t i = 0; i < xs.size(); ++i) mx += xs[i], my += ys[i];
  mx /= double(xs.size()), my /= double(xs.size());
  double sxy = 0, sxx = 0;
  for (size_t i = 0; i < xs.size(); ++i) sxy += (xs[i] - mx) * (ys[i] - my), sxx += (xs[i] - mx) * (xs[i] - mx);
  return sxy / sxx;
}

int64_t principal_components_for(const torch::Tensor& spectra, double fraction) {
  const torch::Tensor S = subsample_rows(spectra.to(torch::kFloat64));
  if (S.size(0) < 2) return 0;
  const torch::Tensor X = S - S.mean(0, true);
  const torch::Tensor ev = torch::linalg_eigvalsh(X.t().mm(X), "L").flip(0).clamp_min(0);
  const double total = ev.sum().item<double>();
  if (!(total > 0)) return 0;
  const torch::Tensor cum = ev.cumsum(0) / total;
  for (int64_t k = 0; k < cum.size(0); ++k)
    if (cum[k].item<double>() >= fraction - 1e-12) return k + 1;
  return cum.size(0);
}

double rgb_unexplained_residual(const torch::Tensor& rgb, const torch::Tensor& spectra) {
  const torch::Tensor S = subsample_rows(spectra.to(torch::kFloat64));
  const torch::Tensor C = subsample_rows(rgb.to(torch::kFloat64));
  const double norm = S.norm().item<double>();
  if (!(norm > 0)) return 0.0;
  const torch::Tensor M = std::get<0>(torch::linalg_lstsq(C, S, c10::nullopt, c10::string_view("gelsd")));
  return (S - C.mm(M)).norm().item<double>() / norm;
}

std::vector<double> inverse_depth_histogram(const torch::Tensor& depth_m, const torch::Tensor& valid, double near_m,
                                            double far_m, int64_t bins) {
  std::vector<double> h(size_t(bins), 0.0);
  const torch::Tensor d = depth_m.to(torch::kFloat64).masked_select(valid.to(torch::kBool));
  if (d.numel() == 0) return h;
  const double a = 1.0 / far_m, b = 1.0 / near_m;
  const torch::Tensor idx = ((1.0 / d.clamp_min(1e-9) - a) / (b - a) * double(bins)).floor().clamp(0, double(bins - 1)).to(torch::kLong);
  const torch::Tensor counts = torch::bincount(idx, {}, bins).to(torch::kFloat64) / double(d.numel());
  for (int64_t i = 0; i < bins; ++i) h[size_t(i)] = counts[i].item<double>();
  return h;
}

namespace {
std::vector<double> quarters(const std::vector<double>& h) {
  std::vector<double> q(4, 0.0);
  const size_t per = h.size() / 4;
  for (size_t i = 0; i < h.size(); ++i) q[std::min<size_t>(3, i / std::max<size_t>(1, per))] += h[i];
  return q;
}
}  // namespace

RealismSpec with_band_weights(RealismSpec spec) {
  spec.ybar = cmf_bands(spec.wavelengths_m, spec.band_width_m)[1].to(torch::kFloat64);
  spec.camera_rgb = optics::camera_response(spec.camera, spec.wavelengths_m, spec.band_width_m).to(torch::kFloat64);
  spec.d65 = optics::illuminant_bands("D65", spec.wavelengths_m, spec.band_width_m).to(torch::kFloat64);
  return spec;
}

SceneRealism measure_realism(const SpectralScene& scene, const RealismSpec& spec, const std::string& name,
                             bool has_depth) {
  if (spec.depth_bins < 4 || spec.depth_bins % 4) throw InputError("realism: depth_bins must be a multiple of 4");
  const int64_t L = scene.spectral.size(0), H = scene.spectral.size(1), W = scene.spectral.size(2);
  if (int64_t(spec.wavelengths_m.size()) != L) throw InputError("realism: the scene's bands differ from the spec's");
  const RealismSpec w = spec.ybar.defined() ? spec : with_band_weights(spec);
  const torch::Tensor illum = scene.kind == SpectralKind::Reflectance ? w.d65 : torch::ones({L}, f64);
  const torch::Tensor ybar = w.ybar * illum;                     // [L]
  const torch::Tensor ywt = ybar / ybar.sum().clamp_min(1e-30);  // a white (or unit radiance) has Y = 1
  const torch::Tensor omega = w.camera_rgb * illum.view({1, L});     // [3, L]
  const torch::Tensor S = scene.spectral.to(torch::kFloat64).reshape({L, H * W});
  const torch::Tensor valid = scene.mask.defined() ? (scene.mask.reshape({H, W}) > 0.5) : torch::ones({H, W}, torch::kBool);
  const torch::Tensor lum = torch::mv(S.t(), ywt).view({H, W});
  SceneRealism r;
  r.name = name;
  r.has_depth = has_depth;
  r.valid_pixels = valid.sum().item<int64_t>();
  r.textured_fraction = textured_fraction(lum, valid);
  r.psd_slope = power_spectrum_slope(lum, valid);
  const torch::Tensor idx = valid.reshape(-1).nonzero().squeeze(1);
  const torch::Tensor Sv = S.index_select(1, idx).t();  // [N, L]
  r.pcs_99 = principal_components_for(Sv);
  r.rgb_unexplained = rgb_unexplained_residual(Sv.mm(omega.t()), Sv);
  if (has_depth) {
    r.inv_depth_hist = inverse_depth_histogram(scene.depth_m.reshape({H, W}), valid, spec.near_m, spec.far_m, spec.depth_bins);
    r.inv_depth_quarters = quarters(r.inv_depth_hist);
    r.depth_structure = depth_structure(scene.depth_m.reshape({H, W}), valid.to(torch::kFloat32));
  }
  return r;
}

RealismSummary summarise_realism(std::vector<SceneRealism> scenes) {
  RealismSummary s;
  s.scenes = std::move(scenes);
  SceneRealism& m = s.mean;
  m.name = "mean";
  const double n = double(std::max<size_t>(1, s.scenes.size()));
  double pcs = 0, pixels = 0, structure = 0, with_structure = 0;
  for (const auto& r : s.scenes) {
    m.textured_fraction += r.textured_fraction / n;
    m.psd_slope += r.psd_slope / n;
    m.rgb_unexplained += r.rgb_unexplained / n;
    pcs += double(r.pcs_99) / n;
    m.valid_pixels += r.valid_pixels;
    if (r.has_depth) {
      if (m.inv_depth_hist.empty()) m.inv_depth_hist.assign(r.inv_depth_hist.size(), 0.0);
      for (size_t i = 0; i < r.inv_depth_hist.size() && i < m.inv_depth_hist.size(); ++i)
        m.inv_depth_hist[i] += r.inv_depth_hist[i] * double(r.valid_pixels);
      pixels += double(r.valid_pixels);
      if (std::isfinite(r.depth_structure)) structure += r.depth_structure, with_structure += 1;
    }
  }
  m.pcs_99 = int64_t(std::lround(pcs));
  m.has_depth = pixels > 0;
  for (auto& v : m.inv_depth_hist) v /= std::max(1.0, pixels);
  if (m.has_depth) m.inv_depth_quarters = quarters(m.inv_depth_hist);
  m.depth_structure = with_structure > 0 ? structure / with_structure : std::nan("");
  return s;
}

std::vector<std::string> check_realism(const SceneRealism& m, const RealismTargets& t) {
  std::vector<std::string> out;
  char buf[200];
  auto line = [&](bool ok, const std::string& text) { out.push_back(text + (ok ? ": met" : ": NOT met")); };
  std::snprintf(buf, sizeof buf, "textured fraction %.3f (target >= %.2f)", m.textured_fraction, t.textured_min);
  line(m.textured_fraction >= t.textured_min, buf);
  std::snprintf(buf, sizeof buf, "power-spectrum slope %.2f (target %.1f .. %.1f)", m.psd_slope, t.slope_lo, t.slope_hi);
  line(m.psd_slope >= t.slope_lo && m.psd_slope <= t.slope_hi, buf);
  std::snprintf(buf, sizeof buf, "RGB-unexplained residual %.3f (target >= %.2f)", m.rgb_unexplained, t.rgb_unexplained_min);
  line(m.rgb_unexplained >= t.rgb_unexplained_min, buf);
  if (m.has_depth) {
    const double qmin = *std::min_element(m.inv_depth_quarters.begin(), m.inv_depth_quarters.end());
    std::snprintf(buf, sizeof buf, "smallest inverse-depth quarter %.3f of the pixels (target >= %.2f)", qmin, t.quarter_min);
    line(qmin >= t.quarter_min, buf);
  }
  return out;
}

namespace {
Json scene_json(const SceneRealism& r) {
  Json j{{"name", r.name},
         {"valid_pixels", r.valid_pixels},
         {"textured_fraction", r.textured_fraction},
         {"psd_slope", r.psd_slope},
         {"pcs_99", r.pcs_99},
         {"rgb_unexplained", r.rgb_unexplained}};
  if (r.has_depth) j["inv_depth_hist"] = r.inv_depth_hist, j["inv_depth_quarters"] = r.inv_depth_quarters;
  if (std::isfinite(r.depth_structure)) j["depth_structure"] = r.depth_structure;
  return j;
}
std::string row(const SceneRealism& r) {
  char buf[256];
  std::string q = "-";
  if (r.has_depth) {
    q.clear();
    for (double v : r.inv_depth_quarters) {
      char b[16];
      std::snprintf(b, sizeof b, "%s%.2f", q.empty() ? "" : " ", v);
      q += b;
    }
  }
  char ds[16] = "-";
  if (std::isfinite(r.depth_structure)) std::snprintf(ds, sizeof ds, "%.2f", r.depth_structure);
  std::snprintf(buf, sizeof buf, "| %s | %.3f | %.2f | %lld | %.3f | %s | %s |\n", r.name.c_str(), r.textured_fraction,
                r.psd_slope, (long long)r.pcs_99, r.rgb_unexplained, q.c_str(), ds);
  return buf;
}
}  // namespace

Json realism_json(const RealismSummary& s, const SceneRealism* reference) {
  Json scenes = Json::array();
  for (const auto& r : s.scenes) scenes.push_back(scene_json(r));
  Json targets = Json::array();
  for (const auto& l : check_realism(s.mean)) targets.push_back(l);
  Json j{{"scenes", scenes}, {"mean", scene_json(s.mean)}, {"targets", targets}};
  if (reference) j["reference"] = scene_json(*reference);
  return j;
}

std::string realism_markdown(const RealismSummary& s, const SceneRealism* reference) {
  std::string md =
      "| scene | textured fraction | PSD slope | PCs for 99 % | RGB-unexplained | inverse-depth quarters (far .. near) | "
      "depth structure |\n"
      "|---|---|---|---|---|---|---|\n";
  for (const auto& r : s.scenes) md += row(r);
  SceneRealism m = s.mean;
  m.name = "**mean**";
  md += row(m);
  if (reference) md += row(*reference);
  return md;
}

}  // namespace hsd::data
