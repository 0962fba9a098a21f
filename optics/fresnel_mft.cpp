#include "optics/fresnel_mft.h"

#include <cmath>

#include <ATen/CPUGeneratorImpl.h>
#include <ATen/Parallel.h>
#include <torch/torch.h>

namespace hsd::optics {

torch::Tensor wrap_phase(const torch::Tensor& phase_rad) {
  return torch::remainder(phase_rad + M_PI, 2.0 * M_PI) - M_PI;
}

torch::Tensor phasor(const torch::Tensor& phase_rad, c10::ScalarType complex_dtype) {
  const auto real_dtype = c10::toRealValueType(complex_dtype);
  const torch::Tensor p = wrap_phase(phase_rad.to(torch::kFloat64)).to(real_dtype);
  return torch::complex(torch::cos(p), torch::sin(p));
}

torch::Tensor compute_tilt_kernel(const torch::Tensor& sensor_x_m, const torch::Tensor& pupil_x_m,
                                  double wavelength_m, double sensor_distance_m, c10::ScalarType complex_dtype) {
  const double scale = -2.0 * M_PI / (wavelength_m * sensor_distance_m);
  const torch::Tensor phase = torch::outer(sensor_x_m.to(torch::kFloat64), pupil_x_m.to(torch::kFloat64)) * scale;
  return phasor(phase, complex_dtype);
}

torch::Tensor compute_defocus_chirp(const torch::Tensor& pupil_x_m, double wavelength_m, double depth_m,
                                    double sensor_distance_m, c10::ScalarType complex_dtype) {
  const double k = 2.0 * M_PI / wavelength_m;
  const double curvature = 1.0 / depth_m + 1.0 / sensor_distance_m;
  return phasor(pupil_x_m.to(torch::kFloat64).pow(2) * (0.5 * k * curvature), complex_dtype);
}

torch::Tensor cell_average_factor(const torch::Tensor& slope_rad_per_m, double cell_m) {
  const torch::Tensor u = slope_rad_per_m.to(torch::kFloat64) * (0.5 * cell_m);
  // sin(u)/u, with its series 1 − u²/6 where u is tiny (no 0/0)
  return torch::where(u.abs() < 1e-4, 1.0 - u.pow(2) / 6.0, torch::sin(u) / torch::where(u.abs() < 1e-4, torch::ones_like(u), u));
}

torch::Tensor cell_cross_factor(const torch::Tensor& slope_rad_per_m, double cell_m) {
  const torch::Tensor u = slope_rad_per_m.to(torch::kFloat64) * (0.5 * cell_m);
  // −sinc'(u) = (sin u − u cos u)/u², with its series u/3 − u³/30 where u is tiny
  const torch::Tensor safe = torch::where(u.abs() < 1e-3, torch::ones_like(u), u);
  return torch::where(u.abs() < 1e-3, u / 3.0 - u.pow(3) / 30.0, (torch::sin(u) - u * torch::cos(u)) / safe.pow(2));
}

namespace {

// wrap(s·h) cast to real_dtype, s·h formed in float64. On the CPU one fused
// pass (the five tensor ops it replaces cost 5x as much memory traffic on the
// 25 bands' 512² grids); rint by the 1.5·2^52 trick, exact for |s·h| < 2^50 rad.
torch::Tensor scaled_wrapped_phase(const torch::Tensor& height, double scale, c10::ScalarType real_dtype) {
  if (!height.is_cpu()) return wrap_phase(height.to(torch::kFloat64) * scale).to(real_dtype);
  const torch::Tensor h = height.contiguous();
  torch::Tensor out = torch::empty(h.sizes(), h.options().dtype(real_dtype));
  AT_DISPATCH_FLOATING_TYPES(h.scalar_type(), "wrapped_phase_in", [&] {
    using hin = scalar_t;
    const hin* src = h.data_ptr<hin>();
    AT_DISPATCH_FLOATING_TYPES(real_dtype, "wrapped_phase_out", [&] {
      scalar_t* dst = out.data_ptr<scalar_t>();
      const double inv = 1.0 / (2.0 * M_PI), magic = 6755399441055744.0;  // 1.5 · 2^52
      at::parallel_for(0, h.numel(), 16384, [&](int64_t a, int64_t b) {
        for (int64_t i = a; i < b; ++i) {
          const double p = double(src[i]) * scale;
          const double turns = (p * inv + magic) - magic;  // round to nearest
          dst[i] = scalar_t(p - turns * (2.0 * M_PI));     // in [−π, π]
        }
      });
    });
  });
  return out;
}

// dL/dφ = Im(conj(M) g) · s = (Re M ∂L/∂Im − Im M ∂L/∂Re) · s, one pass on the CPU.
torch::Tensor phase_gradient(const torch::Tensor& field, const torch::Tensor& grad, double scale) {
  const torch::Tensor g = grad.resolve_conj();
  if (!field.is_cpu()) {
    const torch::Tensor m = torch::view_as_real(field), gr = torch::view_as_real(g);
    return (m.select(-1, 0) * gr.select(-1, 1) - m.select(-1, 1) * gr.select(-1, 0)) * scale;
  }
  const torch::Tensor m = torch::view_as_real(field.contiguous()), gr = torch::view_as_real(g.contiguous());
  torch::Tensor out = torch::empty(field.sizes(), m.options());
  AT_DISPATCH_FLOATING_TYPES(m.scalar_type(), "phase_gradient", [&] {
    const scalar_t *mp = m.data_ptr<scalar_t>(), *gp = gr.data_ptr<scalar_t>();
    scalar_t* o = out.data_ptr<scalar_t>();
    const scalar_t sc = scalar_t(scale);
    at::parallel_for(0, field.numel(), 16384, [&](int64_t a, int64_t b) {
      for (int64_t i = a; i < b; ++i) o[i] = (mp[2 * i] * gp[2 * i + 1] - mp[2 * i + 1] * gp[2 * i]) * sc;
    });
  });
  return out;
}

// M = A exp(i φ), φ = wrap(k (η−1) h) formed in float64, as one autograd node:
// dL/dh = k (η−1) Im(conj(M) g) with PyTorch's complex gradient g = ∂L/∂Re M + i ∂L/∂Im M.
// Stores the field itself (the same size as phase plus aperture), so the
// backward pass needs no cos/sin.
struct PupilField : public torch::autograd::Function<PupilField> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::Tensor height, torch::Tensor aperture,
                               double phase_per_metre, int64_t complex_dtype) {
    const auto real_dtype = c10::toRealValueType(c10::ScalarType(complex_dtype));
    const torch::Tensor p = scaled_wrapped_phase(height, phase_per_metre, real_dtype);
    // a·(cos φ + i sin φ): LibTorch 1.13's torch::polar is a scalar loop (1.3 ms
    // for a 512² float32 field, 2.7 ms in float64); cos and sin are vectorised
    // and the whole takes 0.75 ms (1.0 ms). Same values to rounding.
    const torch::Tensor a = aperture.to(real_dtype);
    const torch::Tensor field = torch::complex(a * torch::cos(p), a * torch::sin(p));
    ctx->save_for_backward({field});
    ctx->saved_data["phase_per_metre"] = phase_per_metre;
    ctx->saved_data["height_dtype"] = int64_t(height.scalar_type());
    return field;
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const double scale = ctx->saved_data["phase_per_metre"].toDouble();
    const auto hdt = c10::ScalarType(ctx->saved_data["height_dtype"].toInt());
    return {phase_gradient(ctx->get_saved_variables()[0], grads[0], scale).to(hdt), torch::Tensor(), torch::Tensor(),
            torch::Tensor()};
  }
};

}  // namespace

torch::Tensor compute_pupil_field(const torch::Tensor& aperture, const torch::Tensor& height_m,
                                  double wavelength_m, double refractive_index, c10::ScalarType complex_dtype) {
  const double k = 2.0 * M_PI / wavelength_m;
  return PupilField::apply(height_m, aperture, k * (refractive_index - 1.0), int64_t(complex_dtype));
}

torch::Tensor matrix_fourier_transform(const torch::Tensor& kernels, const torch::Tensor& pupil_field) {
  const int64_t Z = kernels.size(0), M = kernels.size(1), N = kernels.size(2);
  // B_z = K_z M for every z in one GEMM ([Z·M, N] x [N, N]); then F_z = B_z K_zᵀ.
  // Only `kernels` (no grad) is kept for the backward pass; no copies of it are made.
  const torch::Tensor b = torch::mm(kernels.reshape({Z * M, N}), pupil_field).view({Z, M, N});
  return torch::bmm(b, kernels.transpose(1, 2));  // [Z, M, M]
}

namespace {

// Chirps as [Z, G, N] (a [Z, N] tensor is one group).
torch::Tensor chirp_groups(const torch::Tensor& chirps) { return chirps.dim() == 2 ? chirps.unsqueeze(1) : chirps; }

struct MftIntensity : public torch::autograd::Function<MftIntensity> {
  // K_z = Σ_g tilt_g ⊙ chirp_z,g (row-broadcast): tilt [M, N] or [G, M, N], chirps [Z, N] or [Z, G, N].
  static torch::Tensor kernels(const torch::Tensor& tilt, const torch::Tensor& chirps) {
    if (tilt.dim() == 2) return tilt.unsqueeze(0) * chirp_groups(chirps).select(1, 0).unsqueeze(1);  // [Z, M, N]
    return (tilt.unsqueeze(0) * chirp_groups(chirps).unsqueeze(2)).sum(1);
  }
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::Tensor field, torch::Tensor tilt,
                               torch::Tensor chirps) {
    const torch::Tensor F = matrix_fourier_transform(kernels(tilt, chirps), field);  // [Z, M, M]
    ctx->save_for_backward({F, tilt, chirps});
    return intensity(F);
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const torch::Tensor &F = saved[0], &tilt = saved[1], &chirps = saved[2];
    // Only conj(K) is needed: rebuilt from the conjugated factors, not stored.
    const torch::Tensor Kc = kernels(tilt.conj().resolve_conj(), chirps.conj().resolve_conj());  // [Z, M, N]
    const int64_t Z = Kc.size(0), M = Kc.size(1), N = Kc.size(2);
    // I = re² + im²  ->  dL/dF = 2 gI F  (PyTorch's convention for complex gradients)
    const torch::Tensor gF = 2.0 * grads[0] * F;
    // F = B Kᵀ  ->  dL/dB = gF conj(K);   B = K M  ->  dL/dM = Kᴴ dL/dB = conj(K)ᵀ dL/dB
    const torch::Tensor gB = torch::bmm(gF, Kc);  // [Z, M, N]
    const torch::Tensor gM = torch::mm(Kc.view({Z * M, N}).t(), gB.view({Z * M, N}));
    return {gM, torch::Tensor(), torch::Tensor()};
  }
};

// W_z = [right ⊙ chirp_z,1; …; right ⊙ chirp_z,G]: right [r, N], chirps [Z, N] or [Z, G, N] -> [Z, G·r, N].
torch::Tensor group_right(const torch::Tensor& right, const torch::Tensor& chirps) {
  const torch::Tensor c = chirp_groups(chirps);
  const int64_t Z = c.size(0), G = c.size(1), r = right.size(0), N = right.size(1);
  if (G == 1) return right.unsqueeze(0) * c;  // [Z, r, N]
  return (right.unsqueeze(0).unsqueeze(0) * c.unsqueeze(2)).reshape({Z, G * r, N});
}

struct MftIntensityLowRank : public torch::autograd::Function<MftIntensityLowRank> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::Tensor field, torch::Tensor left,
                               torch::Tensor right, torch::Tensor chirps) {
    const int64_t Z = chirps.size(0), N = right.size(1);
    const torch::Tensor w = group_right(right, chirps);                                  // [Z, G·r, N]
    const int64_t R = w.size(1);
    const torch::Tensor b = torch::mm(w.reshape({Z * R, N}), field).view({Z, R, N});     // W_z M
    const torch::Tensor c = torch::bmm(b, w.transpose(1, 2));                            // [Z, r, r]
    const int64_t M = left.size(0);
    // F_z = L C_z Lᵀ as two plain 2-D GEMMs over all z (broadcast matmul/bmm of
    // these shapes take LibTorch's slow per-batch path, ~10-20× slower):
    // G = C Lᵀ as [Z·r, r] x [r, M]; F = L [G_1 ... G_Z] as [M, r] x [r, Z·M].
    const torch::Tensor g = torch::mm(c.reshape({Z * R, R}), left.t()).view({Z, R, M});
    const torch::Tensor F =
        torch::mm(left, g.permute({1, 0, 2}).reshape({R, Z * M})).view({M, Z, M}).permute({1, 0, 2}).contiguous();
    ctx->save_for_backward({F, left, right, chirps});
    return intensity(F);
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const torch::Tensor &F = saved[0], &left = saved[1], &right = saved[2], &chirps = saved[3];
    const int64_t Z = chirps.size(0), R = left.size(1), N = right.size(1);
    const torch::Tensor gF = 2.0 * grads[0] * F;                                         // I = re² + im²
    // F = L C Lᵀ -> dC = Lᴴ dF conj(L);  C = B Wᵀ -> dB = dC conj(W);  B = W M -> dM = Wᴴ dB
    const torch::Tensor lc = left.conj().resolve_conj();
    const int64_t M = left.size(0);
    // dC_z = Lᴴ dF_z conj(L) = conj(L)ᵀ (dF_z conj(L)), as two 2-D GEMMs over all z.
    const torch::Tensor t1 = torch::mm(gF.reshape({Z * M, M}), lc).view({Z, M, R});
    const torch::Tensor gC =
        torch::mm(lc.t(), t1.permute({1, 0, 2}).reshape({M, Z * R})).view({R, Z, R}).permute({1, 0, 2}).contiguous();
    const torch::Tensor wc = group_right(right.conj().resolve_conj(), chirps.conj().resolve_conj());
    const torch::Tensor gB = torch::bmm(gC, wc);                                         // [Z, r, N]
    const torch::Tensor gM = torch::mm(wc.view({Z * R, N}).t(), gB.view({Z * R, N}));
    return {gM, torch::Tensor(), torch::Tensor(), torch::Tensor()};
  }
};

struct MftIntensityDepthBasis : public torch::autograd::Function<MftIntensityDepthBasis> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, torch::Tensor field, torch::Tensor left,
                               torch::Tensor basis) {
    const int64_t Z = left.size(0), M = left.size(1), R = left.size(2);
    const torch::Tensor y = torch::mm(torch::mm(basis, field), basis.t());         // B M Bᵀ [R, R]
    const torch::Tensor g = torch::mm(left.reshape({Z * M, R}), y).view({Z, M, R});  // L_z Y
    const torch::Tensor F = torch::bmm(g, left.transpose(1, 2));                   // [Z, M, M]
    ctx->save_for_backward({F, left, basis});
    return intensity(F);
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const torch::Tensor &F = saved[0], &left = saved[1], &basis = saved[2];
    const int64_t Z = left.size(0), M = left.size(1), R = left.size(2);
    const torch::Tensor gF = 2.0 * grads[0] * F;  // I = re² + im²
    // F_z = L_z Y L_zᵀ -> dY = Σ_z L_zᴴ dF_z conj(L_z);  Y = T Bᵀ -> dT = dY conj(B);  T = B M -> dM = Bᴴ dT
    const torch::Tensor lc = left.conj().resolve_conj();
    const torch::Tensor t1 = torch::bmm(gF, lc);                                           // [Z, M, R]
    const torch::Tensor gY = torch::mm(lc.reshape({Z * M, R}).t(), t1.reshape({Z * M, R}));  // [R, R]
    const torch::Tensor bc = basis.conj().resolve_conj();
    const torch::Tensor gM = torch::mm(bc.t(), torch::mm(gY, bc));                        // [N, N]
    return {gM, torch::Tensor(), torch::Tensor()};
  }
};

}  // namespace

LowRankKernel factor_tilt_kernel(const torch::Tensor& tilt, double rel_tol, c10::ScalarType complex_dtype) {
  // Truncated SVD T ≈ U_r S_r V_rᴴ [M, N] through the smaller Gram matrix,
  // a Hermitian eigenproblem in float64:
  //   M ≤ N: G = T Tᴴ [M, M] = U S² Uᴴ, left = U_r S_r, right = S_r⁻¹ U_rᴴ T = V_rᴴ;
  //   M > N: G = Tᴴ T [N, N] = V S² Vᴴ, right = V_rᴴ, left = T V_r = U_r S_r;
  // either way left·right is the exact projection onto the kept subspace.
  // Squaring in G costs nothing at the cut: σ_r/σ_0 ≥ rel_tol ≥ 1e-7 keeps
  // σ² ≥ 1e-14 σ_0², above float64's rounding of G (~1e-16 σ_0²). Several
  // times faster than an SVD of T, and it does not fail where LAPACK's complex
  // divide-and-conquer SVD does (large windows: M = P·n > N rows, seen at a
  // 253-px window on a 256-sample DOE). An SVD only for cuts below 1e-7.
  const torch::Tensor T = tilt.to(torch::kComplexDouble);
  const int64_t M = T.size(0), N = T.size(1);
  torch::Tensor S, U, V;  // descending singular values; left (M ≤ N) or right (M > N) singular vectors
  torch::Tensor Vh;       // from an SVD
  if (rel_tol < 1e-7) {
    std::tie(U, S, Vh) = torch::linalg_svd(T, /*full_matrices=*/false);
  } else {
    const torch::Tensor G = M <= N ? torch::mm(T, T.conj().transpose(0, 1)) : torch::mm(T.conj().transpose(0, 1), T);
    const auto eig = torch::linalg_eigh(G);  // ascending eigenvalues
    S = std::get<0>(eig).flip(0).clamp_min(0.0).sqrt();
    (M <= N ? U : V) = std::get<1>(eig).flip(1);
  }
  const int64_t r = std::max<int64_t>(1, (S > rel_tol * S[0].item<double>()).sum().item<int64_t>());
  const torch::Tensor Sr = S.narrow(0, 0, r).to(torch::kComplexDouble);
  LowRankKernel k;
  if (V.defined()) {
    const torch::Tensor Vr = V.narrow(1, 0, r);
    k.left = torch::mm(T, Vr).to(complex_dtype).contiguous();
    k.right = Vr.conj().transpose(0, 1).to(complex_dtype).contiguous();
    return k;
  }
  const torch::Tensor Ur = U.narrow(1, 0, r);
  k.left = (Ur * Sr.view({1, r})).to(complex_dtype).contiguous();
  k.right = (Vh.defined() ? Vh.narrow(0, 0, r) : torch::mm(Ur.conj().transpose(0, 1), T) / Sr.view({r, 1}))
                .to(complex_dtype)
                .contiguous();
  return k;
}

DepthBasis factor_depth_kernels(const torch::Tensor& kernels, double rel_tol, c10::ScalarType complex_dtype) {
  const int64_t Z = kernels.size(0), M = kernels.size(1), N = kernels.size(2);
  const torch::Tensor X = kernels.to(torch::kComplexDouble).reshape({Z * M, N});
  // The dominant right singular vectors of X are the dominant eigenvectors of
  // the Hermitian Gram matrix XᴴX [N, N] (float64: the cut rel_tol ≥ 1e-7
  // keeps σ² above its rounding, as in factor_tilt_kernel). The stack's rank
  // is far below N, so its leading eigenvectors come from a randomised range
  // finder (Halko, Martinsson & Tropp, SIAM Rev. 53, 217 (2011)) on p columns
  // and a Rayleigh-Ritz step, p doubled until the cut falls 8 columns inside
  // them; p = N is the full eigendecomposition. No power iteration: XᴴX
  // already squares the singular values, and its square would push those at
  // the cut (σ⁴ ~ 1e-16 σ_max⁴ at rel_tol 1e-4) below float64's rounding.
  // The random test matrix comes from a fixed private generator: the factors
  // are deterministic and torch's global generator is not touched.
  const torch::Tensor gram = torch::mm(X.conj().t(), X);
  auto gen = at::make_generator<at::CPUGeneratorImpl>(/*seed=*/20211011);
  int64_t p = std::min<int64_t>(N, std::max<int64_t>(16, M / 2));
  torch::Tensor S, V;  // singular values (descending) and right singular vectors [N, p]
  int64_t r = 0;
  for (;;) {
    torch::Tensor Q;
    if (p >= N) {
      Q = torch::eye(N, X.options());
    } else {
      const torch::Tensor omega = torch::randn({N, p}, gen, torch::TensorOptions().dtype(torch::kComplexDouble)).to(X.device());
      Q = std::get<0>(torch::linalg_qr(torch::mm(gram, omega)));  // [N, p], orthonormal columns
    }
    const auto eig = torch::linalg_eigh(torch::mm(Q.conj().t(), torch::mm(gram, Q)));  // ascending
    S = std::get<0>(eig).flip(0).clamp_min(0.0).sqrt();
    V = torch::mm(Q, std::get<1>(eig).flip(1));
    const double smax = S[0].item<double>();
    r = std::max<int64_t>(1, (S > rel_tol * smax).sum().item<int64_t>());
    if (p >= N || r + 8 <= p) break;  // the cut lies inside the captured subspace, with a margin
    p = std::min<int64_t>(N, 2 * p);
  }
  const torch::Tensor Vr = V.narrow(1, 0, r);  // [N, R]
  DepthBasis out;
  out.basis = Vr.conj().t().to(complex_dtype).contiguous();                     // B = V_Rᴴ
  out.left = torch::mm(X, Vr).view({Z, M, r}).to(complex_dtype).contiguous();  // L = X V_R
  return out;
}

torch::Tensor mft_intensity_depth_basis(const DepthBasis& kernel, const torch::Tensor& pupil_field) {
  return MftIntensityDepthBasis::apply(pupil_field, kernel.left, kernel.basis);
}

torch::Tensor mft_intensity_low_rank(const LowRankKernel& kernel, const torch::Tensor& chirps,
                                     const torch::Tensor& pupil_field) {
  return MftIntensityLowRank::apply(pupil_field, kernel.left, kernel.right, chirps);
}

torch::Tensor mft_intensity(const torch::Tensor& tilt, const torch::Tensor& chirps, const torch::Tensor& pupil_field) {
  return MftIntensity::apply(pupil_field, tilt, chirps);
}

torch::Tensor intensity(const torch::Tensor& field) {
  // re² + im² on strided views (a sum over a trailing axis of 2 is 2× slower).
  const torch::Tensor re = torch::real(field), im = torch::imag(field);
  return re * re + im * im;
}

}  // namespace hsd::optics
