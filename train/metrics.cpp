#include "train/metrics.h"

#include <algorithm>
#include <cmath>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::train {

namespace F = torch::nn::functional;

namespace {
// The valid-pixel weights [1, H, W] of a mask (1 = valid), or undefined for all pixels.
torch::Tensor valid(const torch::Tensor& mask, const torch::Tensor& like) {
  if (!mask.defined()) return {};
  if (mask.dim() != 3 || mask.size(0) != 1 || mask.size(1) != like.size(-2) || mask.size(2) != like.size(-1))
    throw InputError("metrics: the mask must be [1, H, W] of the images' size");
  return (mask > 0.5).to(torch::kFloat64);
}
// Mean of x [C, H, W] over the valid pixels of m [1, H, W] (all when m is undefined).
double masked_mean(const torch::Tensor& x, const torch::Tensor& m) {
  if (!m.defined()) return x.mean().item<double>();
  const double n = m.sum().item<double>() * double(x.size(0));
  if (!(n > 0)) throw InputError("metrics: the mask has no valid pixel");
  return (x * m).sum().item<double>() / n;
}
// A metric of a non-finite image is undefined: NumericalError (exit 3) naming
// the metric, the image and the first bad element, never a number.
void require_finite(const torch::Tensor& a, const torch::Tensor& b, const char* metric) {
  for (const auto& [t, which] : {std::pair<const torch::Tensor&, const char*>{a, "first (reconstructed)"}, {b, "second (true)"}}) {
    const std::string bad = first_nonfinite(t);
    if (!bad.empty()) throw NumericalError(std::string(metric) + ": the " + which + " image holds " + bad);
  }
}
}  // namespace

torch::Tensor interior_mask(const torch::Tensor& mask, int64_t margin_px) {
  if (!mask.defined() || mask.dim() != 3 || mask.size(0) != 1) throw InputError("interior_mask: the mask must be [1, H, W]");
  if (margin_px < 0) throw InputError("interior_mask: the margin must be >= 0 px");
  torch::Tensor out = (mask > 0.5).to(mask.scalar_type());
  const int64_t H = mask.size(1), W = mask.size(2);
  const int64_t my = std::min(margin_px, H), mx = std::min(margin_px, W);
  out.narrow(1, 0, my).zero_(), out.narrow(1, H - my, my).zero_();
  out.narrow(2, 0, mx).zero_(), out.narrow(2, W - mx, mx).zero_();
  return out;
}

double psnr_db(const torch::Tensor& a, const torch::Tensor& b, double data_range, const torch::Tensor& mask) {
  if (a.sizes() != b.sizes()) throw InputError("PSNR: images differ in size");
  if (!(data_range > 0)) throw InputError("PSNR: data range must be > 0");
  require_finite(a, b, "PSNR");
  const double mse = masked_mean((a.to(torch::kFloat64) - b.to(torch::kFloat64)).pow(2), valid(mask, a));
  if (mse <= 0) return kPsnrCapDb;
  return std::min(kPsnrCapDb, 10.0 * std::log10(data_range * data_range / mse));
}

double ssim(const torch::Tensor& a, const torch::Tensor& b, double data_range, const torch::Tensor& mask) {
  if (a.sizes() != b.sizes() || a.dim() != 3) throw InputError("SSIM: needs two [C, H, W] images of one size");
  require_finite(a, b, "SSIM");
  const int64_t C = a.size(0), win = std::min<int64_t>({11, a.size(1), a.size(2)});
  const double sigma = 1.5;
  torch::Tensor g = torch::arange(win, torch::kFloat64) - double(win - 1) / 2.0;
  g = torch::exp(-g.pow(2) / (2 * sigma * sigma));
  g = g / g.sum();
  const torch::Tensor w = torch::outer(g, g).view({1, 1, win, win}).expand({C, 1, win, win});
  auto filt = [&](const torch::Tensor& x) { return F::conv2d(x.unsqueeze(0), w, F::Conv2dFuncOptions().groups(C))[0]; };
  const torch::Tensor x = a.to(torch::kFloat64), y = b.to(torch::kFloat64);
  const double C1 = std::pow(0.01 * data_range, 2), C2 = std::pow(0.03 * data_range, 2);
  const torch::Tensor mx = filt(x), my = filt(y);
  const torch::Tensor sxx = filt(x * x) - mx * mx, syy = filt(y * y) - my * my, sxy = filt(x * y) - mx * my;
  const torch::Tensor map = ((2 * mx * my + C1) * (2 * sxy + C2)) / ((mx * mx + my * my + C1) * (sxx + syy + C2));
  // The map covers the window positions fully inside the image; a position
  // counts when every pixel of its window is valid (an invalid pixel never
  // enters a counted window).
  torch::Tensor m = valid(mask, a);
  if (m.defined()) {
    const torch::Tensor ones = torch::ones({1, 1, win, win}, torch::kFloat64);
    m = (F::conv2d(m.unsqueeze(0), ones)[0] > double(win * win) - 0.5).to(torch::kFloat64);
    if (!(m.sum().item<double>() > 0)) return std::nan("");  // no fully valid window
  }
  return masked_mean(map, m);
}

torch::Tensor luminance(const torch::Tensor& cube, const torch::Tensor& weights) {
  const torch::Tensor w = weights.to(torch::kFloat64);
  const double s = w.sum().item<double>();
  if (!(s > 0)) throw InputError("luminance: the weights sum to zero");
  const int64_t L = cube.size(0);
  return ((w / s).view({L, 1, 1}) * cube.to(torch::kFloat64)).sum(0, true).to(cube.scalar_type());
}

DepthErrors depth_errors(const torch::Tensor& pred, const torch::Tensor& truth, const torch::Tensor& mask) {
  const std::string bad = first_nonfinite(pred);
  if (!bad.empty()) throw NumericalError("depth errors: the predicted depth map holds " + bad);
  const torch::Tensor e = pred.to(torch::kFloat64) - truth.to(torch::kFloat64);
  const torch::Tensor m = mask.defined() ? (mask > 0.5).to(torch::kFloat64) : torch::ones_like(e);
  const double n = m.sum().item<double>();
  if (!(n > 0)) throw InputError("depth errors: no valid pixel");
  return {std::sqrt((e.pow(2) * m).sum().item<double>() / n), (e.abs() * m).sum().item<double>() / n};
}

torch::Tensor patch_reflectances(const torch::Tensor& radiance, const torch::Tensor& illuminant,
                                 const std::vector<std::array<int64_t, 4>>& boxes) {
  const torch::Tensor e = illuminant.to(torch::kFloat64).clamp_min(1e-12).view({-1, 1, 1});
  const torch::Tensor refl = radiance.to(torch::kFloat64) / e;
  std::vector<torch::Tensor> out;
  for (const auto& b : boxes) {
    if (b[2] <= b[0] || b[3] <= b[1] || b[0] < 0 || b[1] < 0 || b[2] > radiance.size(2) || b[3] > radiance.size(1))
      throw InputError("ColorChecker box outside the image");
    out.push_back(refl.narrow(1, b[1], b[3] - b[1]).narrow(2, b[0], b[2] - b[0]).mean({1, 2}));
  }
  return torch::stack(out);
}

double mean_patch_rmse(const torch::Tensor& recovered, const torch::Tensor& truth) {
  return (recovered.to(torch::kFloat64) - truth.to(torch::kFloat64)).pow(2).mean(1).sqrt().mean().item<double>();
}

}  // namespace hsd::train
