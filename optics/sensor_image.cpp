#include "optics/sensor_image.h"

#include <algorithm>
#include <cmath>

#include <torch/torch.h>

#include "common/error.h"
#include "optics/spectral_sum.h"

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

namespace {

// OTFs of kernels [..., P, P] for real FFTs of size (nh, nw), kernel centre at (0, 0).
torch::Tensor otf(const torch::Tensor& psf, int64_t nh, int64_t nw) {
  const int64_t P = psf.size(-1), r = P / 2;
  torch::Tensor k = F::pad(psf, F::PadFuncOptions({0, nw - P, 0, nh - P}));
  k = torch::roll(k, {-r, -r}, {-2, -1});
  return torch::fft::rfft2(k);
}
// DFT matrix [bins, P] of an n-point transform for a P-tap kernel whose centre
// tap (index r = P/2) sits at 0: E[k, a] = exp(−2πi k (a − r)/n). Phases are
// formed in float64 and reduced mod n before the float cast.
torch::Tensor kernel_dft_matrix(int64_t n, int64_t bins, int64_t P, c10::ScalarType cdt, torch::Device device) {
  const int64_t r = P / 2;
  const torch::Tensor k = torch::arange(bins, torch::kFloat64).view({-1, 1});
  const torch::Tensor a = (torch::arange(P, torch::kFloat64) - double(r)).view({1, -1});
  const torch::Tensor ph = torch::remainder(k * a, double(n)) * (-2.0 * M_PI / double(n));
  return torch::complex(torch::cos(ph), torch::sin(ph)).to(cdt).to(device);
}

// One layer's band-summed spectrum as one autograd node:
//   OTF_λ = E_h K_λ E_wᵀ                    (K_λ = P_λ,z, P×P, centre at (0, 0))
//   S[b, c] = Σ_λ Ω[c, λ] · FFT(I_λ)[b] · OTF_λ      -> [B, C, nh, nw/2+1]
// The OTFs are a small DFT (K E_wᵀ as one GEMM, then E_h per band as a batched
// GEMM, which leaves them contiguous; a permuted copy costs more than the GEMM);
// the band sum and its adjoint are fused loops (spectral_sum.h). Gradient only
// for the PSFs (the radiance and Ω are constants here; render_sensor_image takes
// the generic autograd path when they need a gradient).
struct LayerSpectrum : public torch::autograd::Function<LayerSpectrum> {
  // psf [L, P, P] real; spec [B, L, nh, nwr]; omega [C, L] real;
  // eh [nh, P], ew [nwr, P] (complex, the DFT matrices).
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::Tensor psf, torch::Tensor spec,
                               torch::Tensor omega, torch::Tensor eh, torch::Tensor ew) {
    const int64_t L = psf.size(0), P = psf.size(1), nh = eh.size(0), nwr = ew.size(0), B = spec.size(0),
                  C = omega.size(0);
    const torch::Tensor t = torch::mm(psf.to(eh.scalar_type()).reshape({L * P, P}), ew.t()).view({L, P, nwr});
    const torch::Tensor o = torch::bmm(eh.expand({L, nh, P}), t).view({L, nh * nwr});  // OTFs, contiguous
    std::vector<torch::Tensor> s;
    for (int64_t b = 0; b < B; ++b) s.push_back(spectral_sum(spec[b].reshape({L, nh * nwr}), o, omega).view({C, nh, nwr}));
    ctx->save_for_backward({spec, omega, eh, ew});
    ctx->saved_data["psf_dtype"] = int64_t(psf.scalar_type());
    return torch::stack(s);
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const torch::Tensor &spec = saved[0], &omega = saved[1], &eh = saved[2], &ew = saved[3];
    const int64_t B = spec.size(0), L = spec.size(1), nh = eh.size(0), nwr = ew.size(0), P = eh.size(1),
                  C = omega.size(0);
    const torch::Tensor gs = grads[0].resolve_conj();  // [B, C, nh, nwr]
    // dL/dO_λ = Σ_b conj(FFT(I_λ))[b] · Σ_c Ω[c, λ] dL/dS[b, c]   [L, nh·nwr]
    torch::Tensor go;
    for (int64_t b = 0; b < B; ++b)
      go = spectral_sum_adjoint(spec[b].reshape({L, nh * nwr}), gs[b].reshape({C, nh * nwr}), omega, go);
    // O = E_h T -> dT = E_hᴴ dO;  T = K E_wᵀ -> dK = dT conj(E_w); the PSF is real: Re.
    const torch::Tensor gt = torch::bmm(eh.conj().resolve_conj().t().expand({L, P, nh}), go.view({L, nh, nwr}));
    const torch::Tensor gk = torch::mm(gt.view({L * P, nwr}), ew.conj().resolve_conj()).view({L, P, P});
    const auto dt = c10::ScalarType(ctx->saved_data["psf_dtype"].toInt());
    return {torch::real(gk).to(dt).contiguous(), {}, {}, {}, {}};
  }
};

// The same, composed of differentiable ops (used when the radiance or Ω needs a gradient).
torch::Tensor layer_spectrum_generic(const torch::Tensor& psf, const torch::Tensor& spec, const torch::Tensor& omega,
                                     const torch::Tensor& eh, const torch::Tensor& ew) {
  const int64_t L = psf.size(0), P = psf.size(1), nh = eh.size(0), nwr = ew.size(0);
  const torch::Tensor k = psf.to(eh.scalar_type()).permute({1, 0, 2}).reshape({P, L * P});
  const torch::Tensor t = torch::mm(eh, k).view({nh, L, P}).permute({1, 0, 2}).reshape({L * nh, P});
  const torch::Tensor o = torch::mm(t, ew.t()).view({L, nh, nwr});
  const torch::Tensor prod = torch::view_as_real(spec * o.unsqueeze(0));  // [B, L, nh, nwr, 2]
  return torch::view_as_complex(torch::tensordot(omega, prod, {1}, {1}).permute({1, 0, 2, 3, 4}).contiguous());
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
                                  const torch::Tensor& omega) {
  check_shapes(radiance, masks, psf, omega);
  const int64_t B = radiance.size(0), H = radiance.size(2), W = radiance.size(3);
  const int64_t Z = masks.size(1), P = psf.size(2), r = P / 2, C = omega.size(0);
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r);
  // Bands with any response (leave out the rest).
  std::vector<int64_t> bands;
  const torch::Tensor band_used = (omega.detach().abs().sum(0) > 0).cpu();
  for (int64_t l = 0; l < radiance.size(1); ++l)
    if (band_used[l].item<bool>()) bands.push_back(l);
  torch::Tensor out = torch::zeros({B, C, H, W}, radiance.options());
  if (bands.empty()) return out;
  const torch::Tensor li = torch::tensor(bands, torch::kInt64).to(radiance.device());
  const torch::Tensor rad = radiance.index_select(1, li);
  const torch::Tensor om = omega.to(radiance.dtype()).index_select(1, li);   // [C, L']
  const torch::Tensor ps = psf.to(radiance.dtype()).index_select(0, li);     // [L', Z, P, P]
  // Each band's image FFT, once. Edge replication extends the scene by r.
  const torch::Tensor spec = torch::fft::rfft2(F::pad(rad, F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate)), c10::IntArrayRef{nh, nw});
  const torch::Tensor layer_used = (masks.detach().abs().sum({0, 2, 3}) > 0).cpu();
  const auto cdt = spec.scalar_type();
  const torch::Tensor eh = kernel_dft_matrix(nh, nh, P, cdt, spec.device());
  const torch::Tensor ew = kernel_dft_matrix(nw, nw / 2 + 1, P, cdt, spec.device());
  // The custom node differentiates the PSFs only; otherwise compose generic ops.
  const bool generic = spec.requires_grad() || om.requires_grad();
  for (int64_t z = 0; z < Z; ++z) {
    if (!layer_used[z].item<bool>()) continue;
    // Σ_λ Ω_c,λ FFT(I_λ) OTF_λ,z -> [B, C, nh, nw/2+1], then 3 inverse FFTs per image.
    const torch::Tensor pz = ps.select(1, z);
    const torch::Tensor summed = generic ? layer_spectrum_generic(pz, spec, om, eh, ew)
                                         : LayerSpectrum::apply(pz, spec, om, eh, ew);
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
