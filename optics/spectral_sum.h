// The band sum of the fast sensor path, S[c, f] = Σ_λ Ω[c, λ] X[λ, f] O[λ, f],
// and its adjoint in O, G[λ, f] = conj(X[λ, f]) Σ_c Ω[c, λ] dS[c, f], as fused
// loops on the CPU: one pass over the band spectra instead of a full-size
// temporary per layer (the products are memory-bound; measured 2-3x faster
// than mul + GEMM on 2 cores). Other devices compose torch ops.
#pragma once
#include <torch/types.h>

namespace hsd::optics {

// x, o: complex [L, F]; omega: real [C, L] (same precision) -> complex [C, F].
torch::Tensor spectral_sum(const torch::Tensor& x, const torch::Tensor& o, const torch::Tensor& omega);

// x: complex [L, F]; ds: complex [C, F]; omega real [C, L] -> complex [L, F].
// With `accumulate` defined, adds into it (same shape) and returns it.
torch::Tensor spectral_sum_adjoint(const torch::Tensor& x, const torch::Tensor& ds, const torch::Tensor& omega,
                                   torch::Tensor accumulate = {});

}  // namespace hsd::optics
