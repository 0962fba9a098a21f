// The fused band sum of the fast sensor path and its adjoint against plain
// tensor ops, in float64 and float32, with a zero weight (a band the camera
// does not see) and with accumulation over a batch; and the adjoint identity
// <S(x, o), d> = <o, S*(x, d)> that the backward pass relies on.
#include <catch2/catch.hpp>

#include "common/error.h"
#include "optics/spectral_sum.h"

using namespace hsd;

TEST_CASE("spectral sum: fused loops equal tensor ops and are adjoint", "[sensor]") {
  for (auto cdt : {torch::kComplexDouble, torch::kComplexFloat}) {
    const auto rdt = c10::toRealValueType(cdt);
    const double tol = cdt == torch::kComplexDouble ? 1e-12 : 1e-5;
    const int64_t L = 6, C = 3, F = 5000;  // F not a multiple of the loop's chunk
    torch::manual_seed(3);
    const torch::Tensor x = torch::randn({L, F}, cdt), o = torch::randn({L, F}, cdt), d = torch::randn({C, F}, cdt);
    torch::Tensor omega = torch::rand({C, L}, rdt);
    omega.select(1, 4).zero_();
    const torch::Tensor s = optics::spectral_sum(x, o, omega);
    const torch::Tensor s_ref = torch::mm(omega.to(cdt), x * o);
    CHECK((s - s_ref).abs().max().item<double>() < tol * s_ref.abs().max().item<double>());
    const torch::Tensor g = optics::spectral_sum_adjoint(x, d, omega);
    const torch::Tensor g_ref = x.conj() * torch::mm(omega.t().to(cdt), d);
    CHECK((g - g_ref).abs().max().item<double>() < tol * g_ref.abs().max().item<double>());
    // Accumulation: g + adjoint(x2, d2)
    const torch::Tensor x2 = torch::randn({L, F}, cdt), d2 = torch::randn({C, F}, cdt);
    const torch::Tensor acc = optics::spectral_sum_adjoint(x2, d2, omega, g.clone());
    const torch::Tensor acc_ref = g_ref + x2.conj() * torch::mm(omega.t().to(cdt), d2);
    CHECK((acc - acc_ref).abs().max().item<double>() < tol * acc_ref.abs().max().item<double>());
    // Adjoint in o (real inner product Re<., .>): Re<S(o), d> = Re<o, S*(d)>.
    const double lhs = torch::real((s * d.conj()).sum()).item<double>();
    const double rhs = torch::real((o * g.conj()).sum()).item<double>();
    CHECK(std::abs(lhs - rhs) < tol * 10 * std::abs(lhs) + tol);
  }
  CHECK_THROWS_AS(optics::spectral_sum(torch::randn({2, 4}, torch::kComplexFloat),
                                       torch::randn({3, 4}, torch::kComplexFloat), torch::rand({3, 2})),
                  InputError);
}
