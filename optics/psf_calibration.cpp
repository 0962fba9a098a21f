#include "optics/psf_calibration.h"

#include <cmath>
#include <limits>

#include <torch/torch.h>

#include "common/error.h"
#include "common/fft_size.h"

namespace hsd::optics {
namespace {

constexpr int64_t kMargin = 8;  // px around the P × P box: kept out of the background, padded for the shift

// The 8 neighbours of every pixel, [8, H, W] (edges replicated).
torch::Tensor neighbours(const torch::Tensor& f) {
  namespace F = torch::nn::functional;
  const int64_t H = f.size(0), W = f.size(1);
  const torch::Tensor p = F::pad(f.view({1, 1, H, W}), F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate))[0][0];
  std::vector<torch::Tensor> n;
  for (int64_t dy = 0; dy < 3; ++dy)
    for (int64_t dx = 0; dx < 3; ++dx)
      if (dy != 1 || dx != 1) n.push_back(p.narrow(0, dy, H).narrow(1, dx, W));
  return torch::stack(n);
}

std::pair<double, double> robust_level(const torch::Tensor& v) {
  const double med = v.median().item<double>();
  const double mad = (v - med).abs().median().item<double>();
  return {med, 1.4826 * mad};
}

// Rule 2 of the header on a float64 frame, given its neighbours' median and maximum.
torch::Tensor hot_mask(const torch::Tensor& f, const torch::Tensor& med, const torch::Tensor& top, double sigma,
                       double n_sigma, double ratio) {
  return (f - med > n_sigma * sigma) & (f > ratio * top.clamp_min(sigma));
}

}  // namespace

torch::Tensor find_hot_pixels(const torch::Tensor& frame, double sigma, double n_sigma, double ratio) {
  const torch::Tensor f = frame.to(torch::kFloat64);
  const torch::Tensor n = neighbours(f);
  return hot_mask(f, std::get<0>(n.median(0)), std::get<0>(n.max(0)), sigma, n_sigma, ratio);
}

torch::Tensor fourier_shift(const torch::Tensor& frame, double dy, double dx) {
  const torch::Tensor f = frame.to(torch::kFloat64);
  const int64_t H = f.size(0), W = f.size(1);
  const int64_t Hp = fast_fft_size(H + 2 * kMargin), Wp = fast_fft_size(W + 2 * kMargin);
  torch::Tensor p = torch::zeros({Hp, Wp}, f.options());
  p.narrow(0, 0, H).narrow(1, 0, W).copy_(f);
  const auto opt = torch::TensorOptions().dtype(torch::kFloat64);
  // Frequencies in cycles per pixel. One factor per axis; an axis's Nyquist
  // term (even sizes) gets the real part of its factor, so the result stays real.
  auto axis_ramp = [&](const torch::Tensor& k, double d, int64_t n) {
    const torch::Tensor phase = -2.0 * M_PI * k * d;
    torch::Tensor r = torch::polar(torch::ones_like(phase), phase);
    if (n % 2 == 0) {
      const int64_t nyq = (k.size(0) == n) ? n / 2 : k.size(0) - 1;  // fftfreq: index n/2; rfftfreq: the last
      r[nyq] = std::cos(phase[nyq].item<double>());
    }
    return r;
  };
  const torch::Tensor ramp = axis_ramp(torch::fft::fftfreq(Hp, 1.0, opt), dy, Hp).view({-1, 1}) *
                             axis_ramp(torch::fft::rfftfreq(Wp, 1.0, opt), dx, Wp).view({1, -1});
  const torch::Tensor out = torch::fft::irfft2(torch::fft::rfft2(p) * ramp, std::vector<int64_t>{Hp, Wp});
  // Content shifted off the end wraps to the start of the padded frame: the
  // margin takes it (shifts of up to kMargin px).
  return out.narrow(0, 0, H).narrow(1, 0, W).contiguous();
}

std::pair<double, double> image_centroid(const torch::Tensor& img) {
  const torch::Tensor w = img.to(torch::kFloat64);
  const double tot = w.sum().item<double>();
  const torch::Tensor r = torch::arange(w.size(0), torch::kFloat64), c = torch::arange(w.size(1), torch::kFloat64);
  if (!(std::abs(tot) > 0)) return {double(w.size(0) - 1) / 2, double(w.size(1) - 1) / 2};
  return {(w.sum(1) * r).sum().item<double>() / tot, (w.sum(0) * c).sum().item<double>() / tot};
}

CapturedPsf calibrate_capture(const torch::Tensor& frame, const torch::Tensor& dark, int64_t P,
                              const CalibrationConfig& opt, double saturation,
                              const std::optional<std::pair<double, double>>& axis_px, const std::string& file,
                              bool estimate_background) {
  if (frame.dim() != 2) input_error(file, "expected a single-channel image");
  const int64_t H = frame.size(0), W = frame.size(1), h = P / 2;
  if (H < P || W < P)
    input_error(file, std::to_string(H) + "x" + std::to_string(W) + " px is smaller than the PSF window (optics.psf_size = " +
                          std::to_string(P) + ")");
  const std::string bad = first_nonfinite(frame);
  if (!bad.empty()) input_error(file, "holds " + bad);
  torch::Tensor f = frame.to(torch::kFloat64).clone();
  if (dark.defined()) {
    if (dark.sizes() != frame.sizes())
      input_error(file, "is " + c10::str(frame.sizes()) + " but the dark frame is " + c10::str(dark.sizes()));
    f = f - dark.to(torch::kFloat64);
  }
  CapturedPsf out;
  // Hot pixels first (with a noise level from the whole frame, which the PSF
  // occupies only in part), so that a saturated hot pixel is not a saturated capture.
  const double sigma0 = std::max(0.5, robust_level(f.flatten()).second);
  const torch::Tensor nb = neighbours(f), nb_median = std::get<0>(nb.median(0));  // once: the test and the repair
  const torch::Tensor hot = hot_mask(f, nb_median, std::get<0>(nb.max(0)), sigma0, opt.hot_pixel_sigma, opt.hot_pixel_ratio);
  out.hot_pixels = hot.sum().item<int64_t>();
  if (out.hot_pixels > 0) f = torch::where(hot, nb_median, f);
  if (saturation > 0) {
    const int64_t sat = ((frame.to(torch::kFloat64) >= saturation) & ~hot).sum().item<int64_t>();
    if (sat > 0)
      input_error(file, std::to_string(sat) + " pixel(s) at the sensor's maximum (" + c10::str(saturation) +
                            " counts): saturated; shorten the exposure");
  }
  // The PSF's box around the smoothed peak; the background outside it.
  namespace F = torch::nn::functional;
  const torch::Tensor smooth =
      F::avg_pool2d(f.view({1, 1, H, W}), F::AvgPool2dFuncOptions(3).stride(1).padding(1).count_include_pad(false))[0][0];
  const int64_t arg = smooth.argmax().item<int64_t>();
  double cr = double(arg / W), cc = double(arg % W);
  const torch::Tensor rows = torch::arange(H, torch::kFloat64).view({-1, 1}), cols = torch::arange(W, torch::kFloat64).view({1, -1});
  // Background: the frame's outer ring (a sixteenth of its size, >= 4 px), away
  // from the PSF's box; a blurred band spreads its light far beyond its window,
  // so the pixels just outside the box are not background.
  const int64_t ring_w = std::max<int64_t>(4, std::min(H, W) / 16);
  torch::Tensor ring = torch::ones_like(f, torch::kBool);
  if (H > 2 * ring_w && W > 2 * ring_w) ring.narrow(0, ring_w, H - 2 * ring_w).narrow(1, ring_w, W - 2 * ring_w).fill_(false);
  const torch::Tensor outside = ring & (((rows - cr).abs() > h + kMargin) | ((cols - cc).abs() > h + kMargin));
  torch::Tensor bg_pixels = f.masked_select(outside);
  if (bg_pixels.numel() < 200) {  // too small a frame: its outermost pixels (hold some of the PSF's tail)
    torch::Tensor edge = torch::ones_like(f, torch::kBool);
    edge.narrow(0, 1, H - 2).narrow(1, 1, W - 2).fill_(false);
    bg_pixels = f.masked_select(edge);
  }
  const auto [ring_level, s] = robust_level(bg_pixels);
  const double b = estimate_background ? ring_level : 0.0;
  out.background = b;
  out.noise_sigma = s;
  const torch::Tensor sig = f - b;
  auto check_signal = [&](double peak) {
    out.snr = s > 0 ? peak / s : (peak > 0 ? std::numeric_limits<double>::infinity() : 0.0);
    if (!(out.snr >= opt.min_snr))
      input_error(file, "no signal: the brightest pixel is " + c10::str(out.snr) + " noise sigma above the background (" +
                            "calibration.min_snr = " + c10::str(opt.min_snr) + ")");
  };
  check_signal(sig.max().item<double>());  // before looking for the source: a frame without one has none to find
  // The centroid inside the P × P box, the box re-centred until it stays.
  auto box_at = [&](double r, double c) {
    const int64_t r0 = std::llround(r) - h, c0 = std::llround(c) - h;
    if (r0 < 0 || c0 < 0 || r0 + P > H || c0 + P > W)
      input_error(file, "the point source (row " + c10::str(std::llround(r)) + ", column " + c10::str(std::llround(c)) +
                            ") is within " + std::to_string(h) + " px of the frame's edge: its " + std::to_string(P) +
                            "-px window does not fit");
    return std::make_pair(r0, c0);
  };
  for (int it = 0; it < 20; ++it) {
    const auto [r0, c0] = box_at(cr, cc);
    const auto [dr, dc] = image_centroid(sig.narrow(0, r0, P).narrow(1, c0, P));
    const double nr = double(r0) + dr, nc = double(c0) + dc;
    const bool done = std::abs(nr - cr) < 1e-4 && std::abs(nc - cc) < 1e-4;
    cr = nr, cc = nc;
    if (!std::isfinite(cr) || !std::isfinite(cc)) input_error(file, "no point source found (no light above the background)");
    if (done) break;
  }
  out.centroid_px = {cr, cc};
  {
    const auto [r0, c0] = box_at(cr, cc);
    check_signal(sig.narrow(0, r0, P).narrow(1, c0, P).max().item<double>());
  }
  // Registration: the point lands on the centre pixel of the window.
  const auto [pr, pc] = axis_px ? *axis_px : out.centroid_px;
  const int64_t ir = std::llround(pr), ic = std::llround(pc);
  const int64_t q = h + kMargin;  // the crop shifted: (2q + 1)² around (ir, ic), zero outside the frame
  torch::Tensor crop = torch::zeros({2 * q + 1, 2 * q + 1}, sig.options());
  const int64_t r_lo = std::max<int64_t>(0, ir - q), r_hi = std::min<int64_t>(H, ir + q + 1);
  const int64_t c_lo = std::max<int64_t>(0, ic - q), c_hi = std::min<int64_t>(W, ic + q + 1);
  if (r_hi - r_lo < P || c_hi - c_lo < P || ir - h < 0 || ic - h < 0 || ir + h >= H || ic + h >= W)
    input_error(file, "the registration point (row " + c10::str(pr) + ", column " + c10::str(pc) + ") is within " +
                          std::to_string(h) + " px of the frame's edge");
  crop.narrow(0, r_lo - (ir - q), r_hi - r_lo).narrow(1, c_lo - (ic - q), c_hi - c_lo)
      .copy_(sig.narrow(0, r_lo, r_hi - r_lo).narrow(1, c_lo, c_hi - c_lo));
  const torch::Tensor shifted = fourier_shift(crop, -(pr - double(ir)), -(pc - double(ic)));
  const torch::Tensor win = shifted.narrow(0, kMargin, P).narrow(1, kMargin, P);
  const double total = win.sum().item<double>();
  if (!(total > 0)) input_error(file, "no light in the PSF window after the background is subtracted");
  out.psf = (win / total).contiguous();
  out.energy_in_window = total / std::max(1e-300, sig.sum().item<double>());
  return out;
}

}  // namespace hsd::optics
