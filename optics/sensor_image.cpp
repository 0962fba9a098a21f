#include "optics/sensor_image.h"

#include <algorithm>
#include <cmath>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {

namespace F = torch::nn::functional;

torch::Tensor nearest_layer(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m) {
  if (depth_m.dim() != 4 || depth_m.size(1) != 1)
    throw InputError("depth map must be [B, 1, H, W], got " + c10::str(depth_m.sizes()));
  if (layer_depths_m.empty()) throw InputError("no depth layers");
  const torch::Tensor d = depth_m.detach().to(torch::kFloat64);
  if (!torch::isfinite(d).all().item<bool>()) throw InputError("depth map holds NaN or Inf");
  if (!(d > 0).all().item<bool>()) throw InputError("depth map holds zero or negative depths");
  const torch::Tensor inv_layers = 1.0 / torch::tensor(layer_depths_m, torch::kFloat64).to(d.device());  // [Z]
  return ((1.0 / d).unsqueeze(-1) - inv_layers).abs().argmin(-1);  // [B, 1, H, W]
}

std::vector<int64_t> occupied_layers(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m) {
  const torch::Tensor idx = nearest_layer(depth_m, layer_depths_m).flatten();
  const torch::Tensor counts = torch::bincount(idx, {}, int64_t(layer_depths_m.size())).cpu();
  std::vector<int64_t> out;
  for (int64_t z = 0; z < counts.size(0); ++z)
    if (counts[z].item<int64_t>() > 0) out.push_back(z);
  return out;
}

namespace {
// Separable Gaussian blur of [B, C, H, W] with edge replication.
torch::Tensor gaussian_blur(const torch::Tensor& x, double sigma_px) {
  if (sigma_px <= 0.0) return x;
  const int64_t r = std::max<int64_t>(1, int64_t(std::ceil(3.0 * sigma_px)));
  torch::Tensor k = torch::arange(-r, r + 1, x.options()).pow(2).mul(-0.5 / (sigma_px * sigma_px)).exp();
  k = k / k.sum();
  const int64_t C = x.size(1);
  torch::Tensor y = F::pad(x, F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate));
  y = F::conv2d(y, k.view({1, 1, 1, -1}).expand({C, 1, 1, 2 * r + 1}), F::Conv2dFuncOptions().groups(C));
  y = F::conv2d(y, k.view({1, 1, -1, 1}).expand({C, 1, 2 * r + 1, 1}), F::Conv2dFuncOptions().groups(C));
  return y;
}

void check_shapes(const torch::Tensor& radiance, const torch::Tensor& masks, const torch::Tensor& psf,
                  const torch::Tensor& omega) {
  if (radiance.dim() != 4) throw InputError("radiance must be [B, L, H, W], got " + c10::str(radiance.sizes()));
  if (masks.dim() != 4 || masks.size(0) != radiance.size(0) || masks.size(2) != radiance.size(2) ||
      masks.size(3) != radiance.size(3))
    throw InputError("masks must be [B, Z, H, W] matching the radiance, got " + c10::str(masks.sizes()));
  if (psf.dim() != 4 || psf.size(0) != radiance.size(1) || psf.size(1) != masks.size(1) || psf.size(2) % 2 == 0 ||
      psf.size(2) != psf.size(3))
    throw InputError("psf must be [L, Z, P, P] (P odd) matching radiance bands and mask layers, got " +
                     c10::str(psf.sizes()));
  if (omega.dim() != 2 || omega.size(1) != radiance.size(1))
    throw InputError("camera response must be [C, L], got " + c10::str(omega.sizes()));
}

}  // namespace

int64_t fast_fft_size(int64_t n) {
  for (int64_t m = std::max<int64_t>(n, 1);; ++m) {
    int64_t k = m;
    for (int64_t p : {2, 3, 5})
      while (k % p == 0) k /= p;
    if (k == 1) return m;
  }
}

namespace {

// OTFs of kernels [..., P, P] for real FFTs of size (nh, nw), kernel centre at (0, 0).
torch::Tensor otf(const torch::Tensor& psf, int64_t nh, int64_t nw) {
  const int64_t P = psf.size(-1), r = P / 2;
  torch::Tensor k = F::pad(psf, F::PadFuncOptions({0, nw - P, 0, nh - P}));
  k = torch::roll(k, {-r, -r}, {-2, -1});
  return torch::fft::rfft2(k);
}
// OTFs of P×P kernels [L, P, P] (centre at (0, 0)) on an (nh, nw) real-FFT grid as
// a small DFT, O = E_h K E_wᵀ: two GEMMs whose backward is two GEMMs too. The
// FFT route's backward (LibTorch's r2c adjoint) is a full-size complex FFT per
// band, about 4× the cost here. DFT phases are built in float64 and wrapped.
torch::Tensor otf_dft(const torch::Tensor& psf, int64_t nh, int64_t nw) {
  const int64_t L = psf.size(0), P = psf.size(-1), r = P / 2, nwr = nw / 2 + 1;
  const auto cdt = psf.scalar_type() == torch::kFloat64 ? torch::kComplexDouble : torch::kComplexFloat;
  auto dft = [&](int64_t n, int64_t bins) {  // [bins, P]: exp(−2πi k (a − r)/n)
    const torch::Tensor k = torch::arange(bins, torch::kFloat64).view({-1, 1});
    const torch::Tensor a = (torch::arange(P, torch::kFloat64) - double(r)).view({1, -1});
    const torch::Tensor ph = torch::remainder(k * a, double(n)) * (-2.0 * M_PI / double(n));
    return torch::complex(torch::cos(ph), torch::sin(ph)).to(cdt).to(psf.device());
  };
  const torch::Tensor eh = dft(nh, nh), ew = dft(nw, nwr);
  const torch::Tensor t = torch::mm(psf.to(cdt).reshape({L * P, P}), ew.t()).view({L, P, nwr});     // K E_wᵀ
  return torch::mm(eh, t.permute({1, 0, 2}).reshape({P, L * nwr})).view({nh, L, nwr}).permute({1, 0, 2});  // [L, nh, nwr]
}

}  // namespace

torch::Tensor layer_masks(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m, double sigma_px) {
  const torch::Tensor idx = nearest_layer(depth_m, layer_depths_m);  // [B, 1, H, W]
  const int64_t Z = int64_t(layer_depths_m.size());
  const auto opts = depth_m.options().dtype(depth_m.is_floating_point() ? depth_m.scalar_type() : torch::kFloat32);
  const torch::Tensor onehot =
      (idx == torch::arange(Z, idx.options()).view({1, Z, 1, 1})).to(opts);  // [B, Z, H, W]
  return gaussian_blur(onehot, sigma_px);
}

torch::Tensor render_sensor_image(const torch::Tensor& radiance, const torch::Tensor& masks, const torch::Tensor& psf,
                                  const torch::Tensor& omega, bool leave_out) {
  check_shapes(radiance, masks, psf, omega);
  const int64_t B = radiance.size(0), H = radiance.size(2), W = radiance.size(3);
  const int64_t Z = masks.size(1), P = psf.size(2), r = P / 2, C = omega.size(0);
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r);
  // Bands with any response (leave out the rest).
  std::vector<int64_t> bands;
  const torch::Tensor band_used = (omega.detach().abs().sum(0) > 0).cpu();
  for (int64_t l = 0; l < radiance.size(1); ++l)
    if (!leave_out || band_used[l].item<bool>()) bands.push_back(l);
  torch::Tensor out = torch::zeros({B, C, H, W}, radiance.options());
  if (bands.empty()) return out;
  const torch::Tensor li = torch::tensor(bands, torch::kInt64).to(radiance.device());
  const torch::Tensor rad = radiance.index_select(1, li);
  const torch::Tensor om = omega.to(radiance.dtype()).index_select(1, li);   // [C, L']
  const torch::Tensor ps = psf.to(radiance.dtype()).index_select(0, li);     // [L', Z, P, P]
  // Each band's image FFT, once. Edge replication extends the scene by r.
  const torch::Tensor spec = torch::fft::rfft2(F::pad(rad, F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate)), c10::IntArrayRef{nh, nw});
  const torch::Tensor layer_used = (masks.detach().abs().sum({0, 2, 3}) > 0).cpu();
  for (int64_t z = 0; z < Z; ++z) {
    if (leave_out && !layer_used[z].item<bool>()) continue;
    const torch::Tensor o = otf_dft(ps.select(1, z), nh, nw);  // [L', nh, nw/2+1]
    // Σ_λ Ω_c,λ FFT(I_λ) OTF_λ,z  -> [B, C, nh, nw/2+1]; spectrum times OTF once per band,
    // then the camera weights as a small real matrix over the band axis.
    const torch::Tensor prod = torch::view_as_real(spec * o.unsqueeze(0));  // [B, L', nh, nwr, 2]
    const torch::Tensor summed = torch::view_as_complex(
        torch::tensordot(om, prod, {1}, {1}).permute({1, 0, 2, 3, 4}).contiguous());  // [B, C, nh, nwr]
    const torch::Tensor img = torch::fft::irfft2(summed, c10::IntArrayRef{nh, nw}).narrow(2, r, H).narrow(3, r, W);
    out = out + masks.narrow(1, z, 1) * img;
  }
  return out;
}

torch::Tensor render_sensor_image_occlusion(const torch::Tensor& radiance, const torch::Tensor& alphas,
                                            const torch::Tensor& psf, const torch::Tensor& omega,
                                            const std::vector<double>& layer_depths_m) {
  check_shapes(radiance, alphas, psf, omega);
  const int64_t Z = alphas.size(1);
  if (int64_t(layer_depths_m.size()) != Z) throw InputError("occlusion compositing: one depth per layer needed");
  const int64_t B = radiance.size(0), L = radiance.size(1), H = radiance.size(2), W = radiance.size(3);
  const int64_t P = psf.size(2), r = P / 2, C = omega.size(0), nh = fast_fft_size(H + 2 * r),
                nw = fast_fft_size(W + 2 * r);
  std::vector<int64_t> order(static_cast<size_t>(Z));
  for (int64_t z = 0; z < Z; ++z) order[size_t(z)] = z;
  std::sort(order.begin(), order.end(), [&](int64_t a, int64_t b) { return layer_depths_m[size_t(a)] > layer_depths_m[size_t(b)]; });
  auto pad = [&](const torch::Tensor& x) { return F::pad(x, F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate)); };
  const torch::Tensor om = omega.to(radiance.dtype());
  const torch::Tensor band_used = (om.detach().abs().sum(0) > 0).cpu();
  torch::Tensor out = torch::zeros({B, C, H, W}, radiance.options());
  for (int64_t l = 0; l < L; ++l) {
    if (!band_used[l].item<bool>()) continue;
    const torch::Tensor I = radiance.narrow(1, l, 1);  // [B, 1, H, W]
    torch::Tensor y = torch::zeros({B, 1, H, W}, radiance.options());
    torch::Tensor cum = torch::zeros({B, 1, H, W}, radiance.options());
    for (int64_t z : order) {
      const torch::Tensor a = alphas.narrow(1, z, 1);
      cum = cum + a;
      const torch::Tensor stacked = pad(torch::cat({a * I, a, cum}, 1));  // [B, 3, nh, nw]
      const torch::Tensor conv = torch::fft::irfft2(torch::fft::rfft2(stacked, c10::IntArrayRef{nh, nw}) * otf(psf[l][z].to(radiance.dtype()), nh, nw),
                                                    c10::IntArrayRef{nh, nw})
                                     .narrow(2, r, H)
                                     .narrow(3, r, W);
      // Guarded normalisation: numerators never exceed E (α_k ≤ cumulative α).
      const torch::Tensor E = conv.narrow(1, 2, 1).clamp_min(1e-6);
      const torch::Tensor b = conv.narrow(1, 0, 1) / E, alpha_blur = conv.narrow(1, 1, 1) / E;
      y = y * (1.0 - alpha_blur) + b;  // "over": nearer layers composite on top
    }
    out = out + om.select(1, l).view({1, C, 1, 1}) * y;
  }
  return out;
}

torch::Tensor render_sensor_image_direct(const torch::Tensor& radiance, const torch::Tensor& masks,
                                         const torch::Tensor& psf, const torch::Tensor& omega) {
  check_shapes(radiance, masks, psf, omega);
  const int64_t B = radiance.size(0), L = radiance.size(1), H = radiance.size(2), W = radiance.size(3);
  const int64_t Z = masks.size(1), P = psf.size(2), r = P / 2, C = omega.size(0);
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r);
  torch::Tensor out = torch::zeros({B, C, H, W}, radiance.options());
  for (int64_t l = 0; l < L; ++l) {
    const torch::Tensor padded = F::pad(radiance.narrow(1, l, 1), F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate));
    for (int64_t z = 0; z < Z; ++z) {
      const torch::Tensor conv = torch::fft::irfft2(torch::fft::rfft2(padded, c10::IntArrayRef{nh, nw}) * otf(psf[l][z].to(radiance.dtype()), nh, nw),
                                                    c10::IntArrayRef{nh, nw})
                                     .narrow(2, r, H)
                                     .narrow(3, r, W);  // [B, 1, H, W]
      out = out + omega.to(radiance.dtype()).select(1, l).view({1, C, 1, 1}) * masks.narrow(1, z, 1) * conv;
    }
  }
  return out;
}

}  // namespace hsd::optics
