#include "optics/spectral_sum.h"

#include <algorithm>
#include <vector>

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {

namespace {

constexpr int64_t kChunk = 2048;  // complex samples per task (16-32 KiB per row)

// Interleaved (re, im) arrays; written out so the compiler vectorises them
// (std::complex products call the C99 NaN-recovery routine).
template <typename T>
void sum_cpu(const T* x, const T* o, const T* om, T* s, int64_t L, int64_t C, int64_t F) {
  at::parallel_for(0, (F + kChunk - 1) / kChunk, 1, [&](int64_t c0, int64_t c1) {
    std::vector<T> prod(2 * kChunk);
    for (int64_t chunk = c0; chunk < c1; ++chunk) {
      const int64_t f0 = chunk * kChunk, n = std::min(kChunk, F - f0);
      for (int64_t c = 0; c < C; ++c) std::fill(s + 2 * (c * F + f0), s + 2 * (c * F + f0 + n), T(0));
      for (int64_t l = 0; l < L; ++l) {
        const T* xl = x + 2 * (l * F + f0);
        const T* ol = o + 2 * (l * F + f0);
        T* p = prod.data();
        for (int64_t i = 0; i < n; ++i) {
          const T ar = xl[2 * i], ai = xl[2 * i + 1], br = ol[2 * i], bi = ol[2 * i + 1];
          p[2 * i] = ar * br - ai * bi;
          p[2 * i + 1] = ar * bi + ai * br;
        }
        for (int64_t c = 0; c < C; ++c) {
          const T w = om[c * L + l];
          if (w == T(0)) continue;
          T* sc = s + 2 * (c * F + f0);
          for (int64_t i = 0; i < 2 * n; ++i) sc[i] += w * p[i];
        }
      }
    }
  });
}

template <typename T>
void adjoint_cpu(const T* x, const T* ds, const T* om, T* g, bool accumulate, int64_t L, int64_t C, int64_t F) {
  at::parallel_for(0, (F + kChunk - 1) / kChunk, 1, [&](int64_t c0, int64_t c1) {
    std::vector<T> acc(2 * kChunk);
    for (int64_t chunk = c0; chunk < c1; ++chunk) {
      const int64_t f0 = chunk * kChunk, n = std::min(kChunk, F - f0);
      for (int64_t l = 0; l < L; ++l) {
        T* a = acc.data();
        std::fill(a, a + 2 * n, T(0));
        for (int64_t c = 0; c < C; ++c) {
          const T w = om[c * L + l];
          if (w == T(0)) continue;
          const T* dc = ds + 2 * (c * F + f0);
          for (int64_t i = 0; i < 2 * n; ++i) a[i] += w * dc[i];
        }
        const T* xl = x + 2 * (l * F + f0);
        T* gl = g + 2 * (l * F + f0);
        if (accumulate) {
          for (int64_t i = 0; i < n; ++i) {  // conj(x) · a
            const T ar = xl[2 * i], ai = xl[2 * i + 1], br = a[2 * i], bi = a[2 * i + 1];
            gl[2 * i] += ar * br + ai * bi;
            gl[2 * i + 1] += ar * bi - ai * br;
          }
        } else {
          for (int64_t i = 0; i < n; ++i) {
            const T ar = xl[2 * i], ai = xl[2 * i + 1], br = a[2 * i], bi = a[2 * i + 1];
            gl[2 * i] = ar * br + ai * bi;
            gl[2 * i + 1] = ar * bi - ai * br;
          }
        }
      }
    }
  });
}

void check(const torch::Tensor& x, const torch::Tensor& y, const torch::Tensor& omega, int64_t y_rows) {
  if (x.dim() != 2 || y.dim() != 2 || omega.dim() != 2 || !x.is_complex() || !y.is_complex() ||
      x.size(1) != y.size(1) || omega.size(1) != x.size(0) || y.size(0) != y_rows ||
      x.scalar_type() != y.scalar_type() || omega.scalar_type() != c10::toRealValueType(x.scalar_type()))
    throw InputError("spectral_sum: expected complex [L, F] and [" + std::to_string(y_rows) +
                     ", F] with a real [C, L] weight of the same precision, got " + c10::str(x.sizes()) + ", " +
                     c10::str(y.sizes()) + ", " + c10::str(omega.sizes()));
}

}  // namespace

torch::Tensor spectral_sum(const torch::Tensor& x, const torch::Tensor& o, const torch::Tensor& omega) {
  const int64_t L = x.size(0), C = omega.size(0);
  check(x, o, omega, L);
  if (!x.is_cpu()) return torch::mm(omega.to(x.scalar_type()), x * o);
  const torch::Tensor xc = x.resolve_conj().contiguous(), oc = o.resolve_conj().contiguous(), wc = omega.contiguous();
  torch::Tensor s = torch::empty({C, x.size(1)}, x.options());
  AT_DISPATCH_FLOATING_TYPES(wc.scalar_type(), "spectral_sum", [&] {
    sum_cpu<scalar_t>(reinterpret_cast<const scalar_t*>(xc.data_ptr()), reinterpret_cast<const scalar_t*>(oc.data_ptr()),
                      wc.data_ptr<scalar_t>(), reinterpret_cast<scalar_t*>(s.data_ptr()), L, C, x.size(1));
  });
  return s;
}

torch::Tensor spectral_sum_adjoint(const torch::Tensor& x, const torch::Tensor& ds, const torch::Tensor& omega,
                                   torch::Tensor accumulate) {
  const int64_t L = x.size(0), C = omega.size(0);
  check(x, ds, omega, C);
  if (!x.is_cpu()) {
    const torch::Tensor g = x.conj() * torch::mm(omega.t().to(x.scalar_type()), ds);
    return accumulate.defined() ? accumulate.add_(g) : g;
  }
  const torch::Tensor xc = x.resolve_conj().contiguous(), dc = ds.resolve_conj().contiguous(), wc = omega.contiguous();
  const bool acc = accumulate.defined();
  if (acc && (!accumulate.is_contiguous() || accumulate.sizes() != x.sizes()))
    throw InputError("spectral_sum_adjoint: accumulator must be a contiguous [L, F] tensor");
  torch::Tensor g = acc ? accumulate : torch::empty_like(xc);
  AT_DISPATCH_FLOATING_TYPES(wc.scalar_type(), "spectral_sum_adjoint", [&] {
    adjoint_cpu<scalar_t>(reinterpret_cast<const scalar_t*>(xc.data_ptr()), reinterpret_cast<const scalar_t*>(dc.data_ptr()),
                          wc.data_ptr<scalar_t>(), reinterpret_cast<scalar_t*>(g.data_ptr()), acc, L, C, x.size(1));
  });
  return g;
}

}  // namespace hsd::optics
