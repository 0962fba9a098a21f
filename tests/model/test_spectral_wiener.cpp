// The spectral Wiener cube (model/spectral_wiener.h) and its prior
// (data/spectral_moments.h): closed forms (an invertible camera returns Ω⁻¹ y;
// a flat image returns the prior's LMMSE spectral map; identical layers are
// one layer), recovery of a blurred band through another band's channel,
// agreement with the estimator solved frequency by frequency, a float64
// gradient check, the moments by hand, the noise variance by hand, and the
// network's residual on it (training, checkpoint). The layered cube
// (model/layered_spectral_wiener.h): each layer's cube against the reference
// with that layer alone, its hat weights, and its gain where the depth is known.
#include <catch2/catch.hpp>

#include <torch/torch.h>

#include <filesystem>
#include <memory>

#include "common/error.h"
#include "common/fft_size.h"
#include "data/spectral_moments.h"
#include "doe_gradient_cut.h"
#include "helpers.h"
#include "model/layered_spectral_wiener.h"
#include "model/spectral_wiener.h"
#include "model/tensor_snapshot.h"
#include "model/torchscript_export.h"
#include "model/unet.h"
#include "train/trainer.h"

using namespace hsd;
namespace F = torch::nn::functional;

namespace {

torch::Tensor delta_psfs(int64_t L, int64_t K, int64_t P, c10::ScalarType dtype) {
  torch::Tensor d = torch::zeros({L, K, P, P}, dtype);
  d.select(2, P / 2).select(2, P / 2).fill_(1.0);
  return d;
}

// The estimator of model/spectral_wiener.h written out frequency by
// frequency, independently of its factored products: H_z = Ω diag(K_z(f))
// built explicitly, E = E_z[H_z Σ H_zᴴ] and H̄ = E_z[H_z] averaged, and
// W(f) = S Σ H̄ᴴ (S E + σ² I)⁻¹ by a LAPACK solve; float64 throughout. For an
// H × W image: W [nh, nf, L, 3] and H̄ [nh, nf, 3, L] on its padded FFT grid.
struct ReferenceFilter {
  int64_t r, nh, nw;
  torch::Tensor Wf, Hbar;
};
ReferenceFilter reference_filter(const torch::Tensor& psf, const torch::Tensor& omega, const model::SpectralPrior& prior,
                                 int64_t H, int64_t W) {
  const int64_t P = psf.size(2), r = P / 2;
  const int64_t nh = fast_fft_size(H + 2 * r), nw = fast_fft_size(W + 2 * r);
  const auto cd = torch::kComplexDouble;
  torch::Tensor k = F::pad(psf, F::PadFuncOptions({0, nw - P, 0, nh - P}));
  k = torch::roll(k, {-r, -r}, {2, 3});
  const torch::Tensor Kf = torch::fft::rfft2(k).permute({2, 3, 1, 0});           // [nh, nf, K, L]
  const torch::Tensor Hz = omega.to(cd) * Kf.unsqueeze(-2);                      // [nh, nf, K, 3, L]
  const torch::Tensor Sig = prior.covariance.to(cd);
  const torch::Tensor E = torch::matmul(torch::matmul(Hz, Sig), Hz.conj().transpose(-1, -2)).mean(2);  // [nh, nf, 3, 3]
  const torch::Tensor Hbar = Hz.mean(2);                                                               // [nh, nf, 3, L]
  const torch::Tensor fy = torch::fft::fftfreq(nh, torch::kFloat64).view({-1, 1});
  const torch::Tensor fx = torch::fft::rfftfreq(nw, torch::kFloat64).view({1, -1});
  torch::Tensor S = torch::pow(torch::sqrt(fy.square() + fx.square()) + 1.0 / double(std::max(nh, nw)), -2.0);
  S = S / S.flatten().slice(0, 1).mean();
  S.index_put_({0, 0}, S.index({0, 0}) * 1e4);
  const torch::Tensor Sc = S.to(cd).unsqueeze(-1).unsqueeze(-1);
  const torch::Tensor M = Sc * E + prior.noise_var * torch::eye(3, cd);
  const torch::Tensor rhs = Sc * torch::matmul(Sig, Hbar.conj().transpose(-1, -2));  // S Σ H̄ᴴ [nh, nf, L, 3]
  // W M = rhs  <=>  Mᴴ Wᴴ = rhsᴴ
  const torch::Tensor Wf = torch::linalg_solve(M.conj().transpose(-1, -2), rhs.conj().transpose(-1, -2)).conj().transpose(-1, -2);
  return {r, nh, nw, Wf, Hbar};
}

torch::Tensor reference_cube(const torch::Tensor& image, const torch::Tensor& psf, const torch::Tensor& omega,
                             const model::SpectralPrior& prior) {
  const int64_t L = psf.size(0), H = image.size(2), W = image.size(3);
  const ReferenceFilter f = reference_filter(psf, omega, prior, H, W);
  const int64_t r = f.r, nh = f.nh, nw = f.nw;
  torch::Tensor y = image - torch::matmul(omega, prior.mean).view({1, 3, 1, 1});
  y = F::pad(y, F::PadFuncOptions({r, nw - W - r, r, nh - H - r}).mode(torch::kReplicate));
  const torch::Tensor Y = torch::fft::rfft2(y).permute({2, 3, 0, 1}).unsqueeze(-1);  // [nh, nf, B, 3, 1]
  const torch::Tensor X = torch::matmul(f.Wf.unsqueeze(2), Y).squeeze(-1).permute({2, 3, 0, 1});  // [B, L, nh, nf]
  const torch::Tensor x = torch::fft::irfft2(X, c10::IntArrayRef{nh, nw});
  return x.narrow(2, r, H).narrow(3, r, W) + prior.mean.view({1, L, 1, 1});
}

// (I − W H̄) δ with that W and H̄, δ zero-padded; float64.
torch::Tensor reference_unobserved(const torch::Tensor& delta, const torch::Tensor& psf, const torch::Tensor& omega,
                                   const model::SpectralPrior& prior) {
  const int64_t H = delta.size(2), W = delta.size(3);
  const ReferenceFilter f = reference_filter(psf, omega, prior, H, W);
  const int64_t r = f.r, nh = f.nh, nw = f.nw;
  const torch::Tensor WH = torch::matmul(f.Wf, f.Hbar);                               // [nh, nf, L, L]
  const torch::Tensor d = F::pad(delta, F::PadFuncOptions({r, nw - W - r, r, nh - H - r}));
  const torch::Tensor D = torch::fft::rfft2(d).permute({2, 3, 0, 1}).unsqueeze(-1);  // [nh, nf, B, L, 1]
  const torch::Tensor X = (D - torch::matmul(WH.unsqueeze(2), D)).squeeze(-1).permute({2, 3, 0, 1});
  return torch::fft::irfft2(X, c10::IntArrayRef{nh, nw}).narrow(2, r, H).narrow(3, r, W);
}

// The filter against reference_cube on the same input: the largest difference over the largest value.
double relative_error_to_reference(const torch::Tensor& x, const torch::Tensor& p, const torch::Tensor& omega,
                                   const model::SpectralPrior& prior) {
  const torch::Tensor got = model::spectral_wiener_cube(x, p, omega, prior);
  const torch::Tensor want = reference_cube(x, p, omega, prior);
  REQUIRE(got.sizes() == want.sizes());
  return (got - want).abs().max().item<double>() / want.abs().max().item<double>();
}

}  // namespace

TEST_CASE("spectral Wiener: the 3x3 Hermitian inverse by cofactors equals LAPACK's, and the eigen cut drops only null directions",
          "[spectral_wiener]") {
  torch::manual_seed(11);
  const int64_t F = 40;
  // M = A Aᴴ + 0.1 I per frequency, complex, spanning a few decades in scale
  const torch::Tensor A = torch::randn({F, 3, 3}, torch::kComplexDouble);
  const torch::Tensor scale = torch::pow(10.0, torch::linspace(-6, 2, F, torch::kFloat64)).view({F, 1, 1});
  const torch::Tensor M = (torch::matmul(A, A.conj().transpose(1, 2)) + 0.1 * torch::eye(3, torch::kComplexDouble)) * scale;
  auto at = [&](int64_t i, int64_t j) { return M.select(1, i).select(1, j).contiguous(); };
  const model::Hermitian3Inverse inv = model::hermitian3_inverse(
      {torch::real(at(0, 0)), torch::real(at(1, 1)), torch::real(at(2, 2)), at(0, 1), at(0, 2), at(1, 2)});
  const torch::Tensor r = torch::randn({2, 3, F}, torch::kComplexDouble);  // a batch of 2 right-hand sides
  const auto z = inv.solve(r.select(1, 0), r.select(1, 1), r.select(1, 2));
  const torch::Tensor got = torch::stack({z[0], z[1], z[2]}, 1);                                             // [2, 3, F]
  const torch::Tensor want = torch::linalg_solve(M.unsqueeze(0), r.permute({0, 2, 1}).unsqueeze(3)).squeeze(3).permute({0, 2, 1});
  CHECK(((got - want).abs() / want.abs().clamp_min(1e-300)).max().item<double>() < 1e-9);

  // Σ of rank 2 in 4 bands (plus rounding): two directions kept, Σ rebuilt from them
  const torch::Tensor B = torch::randn({4, 2}, torch::kFloat64);
  const torch::Tensor sig = torch::matmul(B, B.t());
  const model::SpectralDirections d = model::spectral_directions(sig);
  REQUIRE(d.e.numel() == 2);
  CHECK((d.e > 0).all().item<bool>());
  CHECK(torch::allclose(torch::matmul(d.U * d.e.view({1, -1}), d.U.t()), sig, 1e-12, 1e-12));
  CHECK(model::spectral_directions(test::random_spd(5, 1e-3)).e.numel() == 5);
}

TEST_CASE("spectral Wiener: equals the LMMSE estimator solved frequency by frequency", "[spectral_wiener]") {
  torch::manual_seed(21);
  const int64_t L = 5, K = 3;
  const torch::Tensor x = torch::rand({2, 3, 10, 13}, torch::kFloat64);
  const torch::Tensor p = test::random_band_psfs(L, K, 7, 0.05);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), test::random_spd(L, 0.01), 1e-4};
  CHECK(relative_error_to_reference(x, p, omega, prior) < 1e-10);
  // float32 images: filtered in float64, the cube returned in float32
  const torch::Tensor want = reference_cube(x, p, omega, prior);
  const torch::Tensor got32 = model::spectral_wiener_cube(x.to(torch::kFloat32), p, omega, prior);
  CHECK((got32.to(torch::kFloat64) - want).abs().max().item<double>() < 1e-5 * want.abs().max().item<double>());
}

TEST_CASE("spectral Wiener: the paper's 25 bands and 7 layers, a covariance of rank 6, over several frequency blocks",
          "[spectral_wiener]") {
  // The filter factors Σ = V Vᵀ (eigenvalues of rounding size dropped) and
  // forms E_z[H_z Σ H_zᴴ] block by block of frequencies (~2,000 per block
  // at rank 6 and K = 7); a 64×70 image gives 2,952 frequencies, two blocks.
  torch::manual_seed(5);
  const int64_t L = 25, K = 7;
  const torch::Tensor x = torch::rand({2, 3, 64, 70}, torch::kFloat64);
  const torch::Tensor p = test::random_band_psfs(L, K, 9, 0.02);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const torch::Tensor a = torch::rand({L, 6}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), 0.01 * torch::matmul(a, a.t()), 1e-4};
  CHECK(relative_error_to_reference(x, p, omega, prior) < 1e-10);
}

TEST_CASE("spectral Wiener: an invertible camera without blur returns omega^-1 y", "[spectral_wiener]") {
  torch::manual_seed(11);
  const torch::Tensor omega = torch::eye(3, torch::kFloat64) + 0.3 * torch::rand({3, 3}, torch::kFloat64);
  const torch::Tensor x = torch::rand({2, 3, 11, 14}, torch::kFloat64);
  const torch::Tensor y = torch::einsum("cl,blhw->bchw", {omega, x});
  model::SpectralPrior prior{torch::rand({3}, torch::kFloat64), test::random_spd(3, 0.01), 1e-14};
  const torch::Tensor xh = model::spectral_wiener_cube(y, delta_psfs(3, 2, 5, torch::kFloat64), omega, prior);
  REQUIRE(xh.sizes() == x.sizes());
  CHECK((xh - x).abs().max().item<double>() < 1e-6);
}

TEST_CASE("spectral Wiener: a flat image gets the prior's LMMSE spectrum, and identical layers are one layer",
          "[spectral_wiener]") {
  torch::manual_seed(12);
  const int64_t L = 6;
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const torch::Tensor mu = torch::rand({L}, torch::kFloat64), sig = test::random_spd(L, 0.02);
  const torch::Tensor yc = torch::tensor({0.3, 0.5, 0.2}, torch::kFloat64);
  const torch::Tensor y = yc.view({1, 3, 1, 1}).expand({1, 3, 9, 10}).contiguous();
  // Noise far below the DC term's signal: x = μ + Σ Ωᵀ (Ω Σ Ωᵀ)⁻¹ (y − Ω μ), whatever the blur.
  const model::SpectralPrior prior{mu, sig, 1e-12};
  const torch::Tensor st = torch::matmul(sig, omega.t());
  const torch::Tensor expect = mu + torch::matmul(st, torch::linalg_solve(torch::matmul(omega, st), yc - torch::matmul(omega, mu)));
  torch::Tensor blur = torch::rand({L, 1, 7, 7}, torch::kFloat64);
  blur = blur / blur.sum({2, 3}, true);
  const torch::Tensor xh = model::spectral_wiener_cube(y, blur, omega, prior);
  for (int64_t l = 0; l < L; ++l) {
    INFO("band " << l);
    CHECK((xh[0][l] - expect[l]).abs().max().item<double>() < 1e-6);
  }
  // K copies of one layer are that layer (the mixture of equal OTFs).
  const torch::Tensor img = torch::rand({1, 3, 9, 10}, torch::kFloat64);
  const model::SpectralPrior p2{mu, sig, 1e-4};
  const torch::Tensor one = model::spectral_wiener_cube(img, blur, omega, p2);
  const torch::Tensor three = model::spectral_wiener_cube(img, blur.expand({L, 3, 7, 7}), omega, p2);
  // (equal up to rounding: the three copies are summed, then divided by 3)
  CHECK((one - three).abs().max().item<double>() < 1e-11 * one.abs().max().item<double>());
  // Bad input names the problem.
  CHECK_THROWS_AS(model::spectral_wiener_cube(img, blur, omega, {mu, sig, 0.0}), InputError);
  CHECK_THROWS_AS(model::spectral_wiener_cube(img, blur.narrow(0, 0, 3), omega, p2), InputError);
  CHECK_THROWS_AS(model::spectral_wiener_cube(img, blur, omega, {mu.narrow(0, 0, 3), sig, 1e-4}), InputError);
}

TEST_CASE("spectral Wiener: a band blurred in its own channel comes back through a correlated band's sharp channel",
          "[spectral_wiener]") {
  // Two bands seen by two channels each alone (the third sees both a little);
  // band 1's PSF is wide, band 0's a delta, and the bands are correlated
  // (0.95): band 1's detail is recovered from band 0, where a per-channel
  // deconvolution of the noisy image cannot.
  torch::manual_seed(13);
  const int64_t P = 15;
  const torch::Tensor t = torch::arange(P, torch::kFloat64) - double(P / 2);
  torch::Tensor g = torch::exp(-(t.view({-1, 1}).square() + t.view({1, -1}).square()) / (2 * 3.0 * 3.0));
  g = g / g.sum();
  torch::Tensor psf = torch::zeros({2, 1, P, P}, torch::kFloat64);
  psf[0][0][P / 2][P / 2] = 1.0;
  psf[1][0].copy_(g);
  const torch::Tensor omega = torch::tensor({1.0, 0.0, 0.0, 1.0, 0.1, 0.1}, torch::kFloat64).view({3, 2});
  // A scene: one texture u, band 1 = 0.95 u + a little independent texture.
  const torch::Tensor u = F::interpolate(torch::rand({1, 1, 16, 16}, torch::kFloat64),
                                         F::InterpolateFuncOptions().size(std::vector<int64_t>{64, 64}).mode(torch::kBicubic).align_corners(false));
  const torch::Tensor v = F::interpolate(torch::rand({1, 1, 16, 16}, torch::kFloat64),
                                         F::InterpolateFuncOptions().size(std::vector<int64_t>{64, 64}).mode(torch::kBicubic).align_corners(false));
  const torch::Tensor x = torch::cat({u, 0.95 * u + 0.05 * v}, 1);
  // The image: band 1 blurred (replicated borders), each channel its mix.
  const torch::Tensor xp = F::pad(x.narrow(1, 1, 1), F::PadFuncOptions({P / 2, P / 2, P / 2, P / 2}).mode(torch::kReplicate));
  const torch::Tensor b1 = F::conv2d(xp, g.flip({0, 1}).view({1, 1, P, P}));
  const torch::Tensor blurred = torch::cat({x.narrow(1, 0, 1), b1}, 1);
  const torch::Tensor y = torch::einsum("cl,blhw->bchw", {omega, blurred}) + 1e-3 * torch::randn({1, 3, 64, 64}, torch::kFloat64);
  const torch::Tensor xf = x.flatten(2);
  const torch::Tensor mu = xf.mean(2)[0];
  const torch::Tensor cen = xf[0] - mu.view({2, 1});
  const torch::Tensor sig = torch::matmul(cen, cen.t()) / double(cen.size(1));
  const torch::Tensor xh = model::spectral_wiener_cube(y, psf, omega, {mu, sig, 1e-6});
  auto rms = [](const torch::Tensor& a, const torch::Tensor& b) {  // away from the borders
    return (a - b).narrow(2, 16, 32).narrow(3, 16, 32).square().mean().sqrt().item<double>();
  };
  const double blurred_err = rms(b1, x.narrow(1, 1, 1)), recovered = rms(xh.narrow(1, 1, 1), x.narrow(1, 1, 1));
  INFO("band 1 rms error: blurred " << blurred_err << ", spectral Wiener " << recovered);
  CHECK(recovered < 0.25 * blurred_err);
}

TEST_CASE("spectral Wiener: gradients in the image and the PSFs match central differences (float64)", "[spectral_wiener]") {
  torch::manual_seed(14);
  const int64_t L = 4;
  const torch::Tensor x = torch::rand({1, 3, 9, 11}, torch::kFloat64);
  const torch::Tensor p = torch::rand({L, 2, 5, 5}, torch::kFloat64) + 0.1;
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), test::random_spd(L, 0.01), 1e-3};
  const torch::Tensor w = torch::randn({1, L, 9, 11}, torch::kFloat64);
  auto f = [&](const torch::Tensor& xx, const torch::Tensor& pp) {
    return (model::spectral_wiener_cube(xx, pp / pp.sum({2, 3}, true), omega, prior) * w).sum();
  };
  // The DC term's weight (10⁴ S) leaves the sum a roundoff of ~1e-10: a step
  // of 1e-4 keeps the difference quotient's noise below 1e-6 of it.
  for (const auto& g : test::image_psf_gradient_check(f, x, p, 1e-4)) {
    INFO(g.input << " entry " << g.entry);
    CHECK(g.autograd == Approx(g.difference).epsilon(1e-5).margin(1e-9));
  }
}

TEST_CASE("tensor snapshot: the same tensor unwritten matches, and neither a write, an alias's write nor another tensor does",
          "[spectral_wiener]") {
  torch::Tensor a = torch::rand({4, 5});
  const model::TensorSnapshot s(a);
  CHECK(s.matches(a));
  CHECK(s.matches(a.detach()));                      // an alias of the same values
  CHECK_FALSE(s.matches(a.clone()));                 // equal values elsewhere: not known to be the same
  CHECK_FALSE(s.matches(a.narrow(0, 1, 2)));         // a part
  CHECK_FALSE(s.matches(a.t()));                     // other strides
  CHECK_FALSE(s.matches(torch::Tensor()));
  a.detach().add_(1.0);                              // written through an alias
  CHECK_FALSE(s.matches(a));
  const model::TensorSnapshot s2(a);
  a.narrow(0, 0, 1).zero_();                         // written through a view
  CHECK_FALSE(s2.matches(a));
  CHECK_FALSE(model::TensorSnapshot().matches(a));
}

TEST_CASE("spectral Wiener: the network keeps its filter while PSFs, prior and size stay, and drops it when any changes",
          "[spectral_wiener]") {
  torch::manual_seed(21);
  const int64_t L = 6;
  model::NetOptions o;
  o.bands = L, o.base_width = 4, o.levels = 1, o.norm = NormKind::group, o.residual_spectral_wiener = true;
  model::HsdNet net(o, torch::rand({L, 3}));
  const torch::Tensor Om = torch::rand({3, L});
  torch::Tensor mu = torch::rand({L}) * 0.3;
  const torch::Tensor sig = test::random_spd(L, 1e-3).to(torch::kFloat32);
  net->set_spectral_prior(mu, sig, 1e-5, Om);
  torch::Tensor psf = torch::rand({L, 2, 9, 9});
  psf = psf / psf.sum({2, 3}, true);
  net->set_band_psf(psf);
  // The filter made afresh from the network's buffers (its float32 noise variance).
  auto direct = [&](const torch::Tensor& p, const torch::Tensor& x, const torch::Tensor&) {
    return model::spectral_wiener_cube(x, p, Om, net->spectral_prior()).to(torch::kFloat32);
  };
  const torch::Tensor x = torch::rand({2, 3, 20, 24});
  const torch::Tensor first = direct(psf, x, mu);
  for (int k = 0; k < 3; ++k) CHECK(net->spectral_wiener(x).equal(first));  // made, kept, reused: bitwise the same
  psf.mul_(0.9);  // the PSFs written in place
  const torch::Tensor dimmer = direct(psf, x, mu);
  CHECK_FALSE(dimmer.equal(first));
  for (int k = 0; k < 3; ++k) CHECK(net->spectral_wiener(x).equal(dimmer));
  mu = mu * 1.5;  // another prior
  net->set_spectral_prior(mu, sig, 1e-5, Om);
  const torch::Tensor brighter = direct(psf, x, mu);
  CHECK_FALSE(brighter.equal(dimmer));
  for (int k = 0; k < 3; ++k) CHECK(net->spectral_wiener(x).equal(brighter));
  const torch::Tensor x2 = torch::rand({1, 3, 16, 18});  // another size
  for (int k = 0; k < 3; ++k) CHECK(net->spectral_wiener(x2).equal(direct(psf, x2, mu)));
  // PSFs in a graph (the same values, as a training step's) are never served
  // from what was kept: the gradient reaches them every time.
  const torch::Tensor pg = psf.detach().requires_grad_();
  net->set_band_psf(pg);
  for (int k = 0; k < 3; ++k) {
    pg.mutable_grad() = torch::Tensor();
    net->spectral_wiener(x).sum().backward();
    REQUIRE(pg.grad().defined());
    CHECK(pg.grad().abs().max().item<double>() > 0.0);
  }
}

TEST_CASE("spectral moments: mean and covariance by hand, lit and scaled, and the noise variance by hand", "[spectral_wiener][data]") {
  // Two bands, three pixels (one masked out): reflectances (0.2, 0.4), (0.6, 0.2), masked (9, 9).
  data::LoadedScene s;
  s.file = "hand.exr";
  s.scene.spectral = torch::tensor({0.2f, 0.6f, 9.0f, 0.4f, 0.2f, 9.0f}).view({2, 1, 3});
  s.scene.depth_m = torch::ones({1, 1, 3});
  s.scene.mask = torch::tensor({1.0f, 1.0f, 0.0f}).view({1, 1, 3});
  // Two illuminants (1, 1) and (1, 3); intensity s ~ U[1, 2]: E[s] = 1.5, E[s²] = 7/3.
  const torch::Tensor E = torch::tensor({1.0, 1.0, 1.0, 3.0}, torch::kFloat64).view({2, 2});
  const data::SpectralMoments m = data::radiance_moments({s}, E, 1.0, 2.0);
  CHECK(m.pixels == 2);
  // Band means of the lit pixels: band 0 0.4, band 1 0.3 · E_k[e₁] = 0.3 · 2 = 0.6; times E[s].
  CHECK(m.mean[0].item<double>() == Approx(1.5 * 0.4));
  CHECK(m.mean[1].item<double>() == Approx(1.5 * 0.6));
  // Second moments: E[x0²] = (0.04 + 0.36)/2 = 0.2; E[x0 x1] = (0.08 + 0.12)/2 · 2 = 0.2; E[x1²] = (0.16 + 0.04)/2 · 5 = 0.5.
  const double es2 = 7.0 / 3.0;
  CHECK(m.covariance[0][0].item<double>() == Approx(es2 * 0.2 - 0.36));
  CHECK(m.covariance[0][1].item<double>() == Approx(es2 * 0.2 - 0.54));
  CHECK(m.covariance[1][0].item<double>() == Approx(m.covariance[0][1].item<double>()));
  CHECK(m.covariance[1][1].item<double>() == Approx(es2 * 0.5 - 0.81));
  CHECK_THROWS_AS(data::radiance_moments({s}, torch::Tensor(), 1.0, 2.0), InputError);  // a reflectance needs light
  s.scene.mask.zero_();
  CHECK_THROWS_AS(data::radiance_moments({s}, E, 1.0, 2.0), InputError);  // no valid pixel
  // σ² = E[σ_read²] + y / photons, σ_read ~ U[0.001, 0.005]: (1 + 5 + 25)/3 · 1e-6; fixed σ; no noise floored.
  CHECK(model::mean_noise_variance(0.001, 0.005, 17000, 0.34) == Approx(31e-6 / 3 + 0.34 / 17000));
  CHECK(model::mean_noise_variance(-1, 0.005, 0, 0.34) == Approx(25e-6));
  CHECK(model::mean_noise_variance(-1, 0, 0, 0.34) == Approx(1e-8));
}

TEST_CASE("spectral Wiener: the network's residual on it starts at it, trains, reaches the DOE and checkpoints its prior",
          "[spectral_wiener][train]") {
  const Config cfg = load_config(test::source_path("configs/tiny.json"),
                                 {"data.root=\"unused_no_data_is_loaded\"", "model.base_width=4", "model.levels=2",
                                  "train.batch_size=2", "train.warmup_steps=0", "train.decay=none",
                                  "data.patch_size_px=16", "train.lr_net=0.003", "model.residual=\"spectral_wiener\""});
  train::Trainer a(cfg);
  const int64_t L = int64_t(a.psf().spec().wavelengths_m.size());
  REQUIRE(a.net()->options().residual_spectral_wiener);
  a.refresh_preinverse();
  const torch::Tensor x = torch::rand({1, 3, 16, 16});
  CHECK_THROWS_WITH(a.net()->spectral_wiener(x), Catch::Contains("prior"));  // never set: refused, not zeros
  torch::manual_seed(15);
  const torch::Tensor mu = torch::rand({L}) * 0.3, sig = test::random_spd(L, 1e-3).to(torch::kFloat32);
  a.net()->set_spectral_prior(mu, sig, 1e-5, a.sensor().omega);
  a.net()->start_at_baselines(1.0);
  {
    torch::NoGradGuard ng;
    a.net()->eval();
    const model::SpectralPrior prior{mu, sig, 1e-5};
    const torch::Tensor expect = model::spectral_wiener_cube(x, a.psf_stack(), a.sensor().omega, prior);
    CHECK((a.net()->forward(x).hs - expect).abs().max().item<double>() < 1e-6);
    a.net()->train();
  }
  torch::manual_seed(5);
  train::Batch bt;
  bt.radiance = torch::rand({2, L, 16, 16});
  bt.depth_m = 0.5 + torch::rand({2, 1, 16, 16});
  const double first = a.step(bt, 0).loss;
  REQUIRE(a.doe().parameter().grad().defined());
  CHECK(a.doe().parameter().grad().abs().max().item<double>() > 0.0);
  double last = first;
  for (int k = 1; k < 8; ++k) last = a.step(bt, k).loss;
  CHECK(last < first);
  CHECK_FALSE(a.net()->band_psf().requires_grad());
  const std::string ck = (std::filesystem::temp_directory_path() / "hsd_test_spectral_wiener_ck.pt").string();
  a.save_checkpoint(ck, 8);
  train::Trainer c(cfg);
  c.load_checkpoint(ck);
  torch::NoGradGuard ng;
  a.net()->eval(), c.net()->eval();
  a.refresh_preinverse();
  CHECK((c.net()->forward(x).hs - a.net()->forward(x).hs).abs().max().item<double>() < 1e-6);
  std::filesystem::remove(ck);
}

// Trainers on tiny.json with the spectral Wiener residual, one per set of
// extra overrides, all with the same spectral prior, heads at the baselines
// and the first's network weights (so the same forward); and a batch for them.
static std::vector<std::unique_ptr<train::Trainer>> spectral_wiener_trainers(const std::vector<std::string>& extra) {
  std::vector<std::unique_ptr<train::Trainer>> out;
  for (const std::string& e : extra)
    out.push_back(std::make_unique<train::Trainer>(load_config(
        test::source_path("configs/tiny.json"),
        {"data.root=\"unused_no_data_is_loaded\"", "model.base_width=4", "model.levels=2", "train.batch_size=2",
         "train.warmup_steps=0", "train.decay=none", "data.patch_size_px=16", "model.residual=\"spectral_wiener\"", e})));
  const int64_t L = int64_t(out[0]->psf().spec().wavelengths_m.size());
  torch::manual_seed(15);
  const torch::Tensor mu = torch::rand({L}) * 0.3, sig = test::random_spd(L, 1e-3).to(torch::kFloat32);
  for (auto& t : out) {
    t->net()->set_spectral_prior(mu, sig, 1e-5, t->sensor().omega);
    t->net()->start_at_baselines(1.0);
  }
  torch::NoGradGuard ng;
  for (size_t i = 1; i < out.size(); ++i)
    for (const auto& p : out[0]->net()->named_parameters()) out[i]->net()->named_parameters()[p.key()].copy_(p.value());
  return out;
}

static train::Batch spectral_wiener_batch(const train::Trainer& t) {
  const int64_t L = int64_t(t.psf().spec().wavelengths_m.size());
  torch::manual_seed(5);
  train::Batch bt;
  bt.radiance = torch::rand({2, L, 16, 16});
  bt.depth_m = 0.5 + torch::rand({2, 1, 16, 16});
  return bt;
}

TEST_CASE("spectral Wiener: train.spectral_wiener_doe_gradient = false leaves the forward as it is and cuts only the filter's gradient into the DOE",
          "[spectral_wiener][train]") {
  auto t = spectral_wiener_trainers({"train.spectral_wiener_doe_gradient=true", "train.spectral_wiener_doe_gradient=false"});
  test::check_doe_gradient_cut(*t[0], *t[1], spectral_wiener_batch(*t[0]));
}

TEST_CASE("spectral Wiener: train.base_doe_gradient_scale = k scales the base's path into the DOE by k and leaves the network's gradient",
          "[spectral_wiener][train]") {
  // The DOE's gradient is g_other + k g_base: linear in k, with g_base != 0;
  // the base depends on no network parameter, so the network's gradients are
  // the same at every k; the forward (the loss) is too.
  auto t = spectral_wiener_trainers({"train.base_doe_gradient_scale=0", "train.base_doe_gradient_scale=1",
                                     "train.base_doe_gradient_scale=2"});
  const train::Batch bt = spectral_wiener_batch(*t[0]);
  const double l0 = t[0]->step(bt, 0).loss, l1 = t[1]->step(bt, 0).loss, l2 = t[2]->step(bt, 0).loss;
  CHECK(l0 == l1);
  CHECK(l2 == l1);
  const torch::Tensor g0 = t[0]->doe().parameter().grad().to(torch::kFloat64),
                      g1 = t[1]->doe().parameter().grad().to(torch::kFloat64),
                      g2 = t[2]->doe().parameter().grad().to(torch::kFloat64);
  const torch::Tensor base_path = g1 - g0;
  const double size = g1.abs().max().item<double>();
  INFO("the base's path: " << base_path.abs().max().item<double>() << " of " << size);
  CHECK(base_path.abs().max().item<double>() > 1e-3 * size);
  CHECK(((g2 - g1) - base_path).abs().max().item<double>() < 1e-2 * base_path.abs().max().item<double>());
  for (const auto& p : t[0]->net()->named_parameters()) {
    INFO(p.key());
    const torch::Tensor a = p.value().grad(), b = t[2]->net()->named_parameters()[p.key()].grad();
    REQUIRE(a.defined() == b.defined());
    if (a.defined()) CHECK(a.equal(b));
  }
}

TEST_CASE("layered spectral Wiener: each layer's cube is the estimator with that layer alone, and knowing the layer beats the mixture",
          "[spectral_wiener]") {
  torch::manual_seed(31);
  const int64_t L = 5, K = 3, P = 9, H = 64, W = 60;
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const torch::Tensor mu = torch::rand({L}, torch::kFloat64), sig = test::random_spd(L, 0.02);
  // (noise well above rounding: a deconvolution of an image whose borders the
  // filter only replicates must not trust the frequencies its blur nearly removes)
  const model::SpectralPrior prior{mu, sig, 1e-3};
  // layer 0 sharp, layers 1 and 2 ever wider blurs
  torch::Tensor psf = torch::zeros({L, K, P, P}, torch::kFloat64);
  psf.select(1, 0).select(1, P / 2).select(1, P / 2).fill_(1.0);
  for (int64_t z = 1; z < K; ++z) {
    const torch::Tensor g = torch::arange(P, torch::kFloat64) - double(P / 2);
    const torch::Tensor e = torch::exp(-(g.view({-1, 1}).square() + g.view({1, -1}).square()) / (2.0 * double(z) * double(z)));
    psf.select(1, z).copy_((e / e.sum()).expand({L, P, P}));
  }
  const model::SpectralOtf otf = model::spectral_otf(psf, H, W);
  const torch::Tensor img = torch::rand({2, 3, H, W}, torch::kFloat64);
  auto only = [&](int64_t z) {  // every pixel on layer z
    return model::one_hot_layer_weights(torch::full({2, 1, H, W}, z, torch::kInt64), K);
  };
  for (int64_t z = 0; z < K; ++z) {
    INFO("layer " << z);
    const torch::Tensor got = model::layered_spectral_wiener_cube(img, otf, omega, prior, only(z).to(torch::kFloat64));
    const torch::Tensor want = reference_cube(img, psf.narrow(1, z, 1), omega, prior);
    REQUIRE(got.sizes() == want.sizes());
    CHECK((got - want).abs().max().item<double>() < 1e-9 * want.abs().max().item<double>());
  }
  // Weights split between layers give the weighted sum of their cubes.
  torch::Tensor split = torch::zeros({2, K, H, W}, torch::kFloat64);
  split.narrow(1, 0, 1).fill_(0.25), split.narrow(1, 2, 1).fill_(0.75);
  const torch::Tensor mixed = model::layered_spectral_wiener_cube(img, otf, omega, prior, split);
  const torch::Tensor by_hand = 0.25 * reference_cube(img, psf.narrow(1, 0, 1), omega, prior) +
                                0.75 * reference_cube(img, psf.narrow(1, 2, 1), omega, prior);
  CHECK((mixed - by_hand).abs().max().item<double>() < 1e-9 * by_hand.abs().max().item<double>());
  // A scene drawn from the prior, imaged through layer 2 alone: its own layer's
  // cube is closer to it than the mixture over the three layers.
  const torch::Tensor white = torch::randn({1, L, H, W}, torch::kFloat64);
  const torch::Tensor chol = torch::linalg_cholesky(sig);
  torch::Tensor x = mu.view({1, L, 1, 1}) + torch::einsum("lm,bmhw->blhw", {chol, white});
  for (int i = 0; i < 3; ++i)  // a smoother texture, nearer the prior's falling power spectrum
    x = F::avg_pool2d(F::pad(x, F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate)), F::AvgPool2dFuncOptions(3).stride(1));
  const torch::Tensor xp = F::pad(x, F::PadFuncOptions({P / 2, P / 2, P / 2, P / 2}).mode(torch::kReplicate));
  const torch::Tensor blurred = F::conv2d(xp, psf.select(1, 2).unsqueeze(1).flip({2, 3}), F::Conv2dFuncOptions().groups(L));
  const torch::Tensor y = torch::einsum("cl,blhw->bchw", {omega, blurred});
  const torch::Tensor on2 = model::one_hot_layer_weights(torch::full({1, 1, H, W}, 2, torch::kInt64), K);
  const torch::Tensor known = model::layered_spectral_wiener_cube(y, otf, omega, prior, on2);
  const torch::Tensor mixture = model::spectral_wiener_cube(y, psf, omega, prior);
  // (inside a margin of the blur's reach: the filter's replicated borders are not the scene's)
  auto err = [&](const torch::Tensor& c) {
    return (c - x).narrow(2, 2 * P, H - 4 * P).narrow(3, 2 * P, W - 4 * P).square().mean().item<double>();
  };
  const double e_known = err(known), e_mix = err(mixture);
  INFO("squared error, layer known " << e_known << ", mixture " << e_mix);
  CHECK(e_known < 0.8 * e_mix);
  // Bad input names the problem.
  CHECK_THROWS_AS(model::layered_spectral_wiener_cube(img, model::SpectralOtf(), omega, prior, only(0)), InputError);
  CHECK_THROWS_AS(model::layered_spectral_wiener_cube(img, otf, omega, prior, only(0).narrow(1, 0, 2)), InputError);
  CHECK_THROWS_AS(model::one_hot_layer_weights(torch::full({1, 1, 2, 2}, K, torch::kInt64), K), InputError);
  CHECK_THROWS_AS(model::one_hot_layer_weights(torch::full({1, 1, 2, 2}, -1, torch::kInt64), K), InputError);
}

TEST_CASE("layered spectral Wiener: hat weights in inverse depth pick a layer at its depth and split between neighbours",
          "[spectral_wiener]") {
  const std::vector<double> layers{0.5, 2.0, 1.0};  // inverse 2, 0.5, 1: given out of order
  // 0.5 m, 2 m, 1 m, 1/1.5 m (halfway between 1 and 2 m^-1), 1.6 m (a quarter of the way from 0.5 to 1 m^-1), 0.3 m and 5 m (beyond the ends)
  const torch::Tensor d = torch::tensor({0.5, 2.0, 1.0, 1.0 / 1.5, 1.6, 0.3, 5.0}, torch::kFloat64).view({1, 1, 1, 7});
  const torch::Tensor w = model::inverse_depth_layer_weights(d, layers).to(torch::kFloat64)[0].select(1, 0);  // [K, 7]
  const torch::Tensor want = torch::tensor({{1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0},
                                            {0.0, 1.0, 0.0, 0.0, 0.75, 0.0, 1.0},
                                            {0.0, 0.0, 1.0, 0.5, 0.25, 0.0, 0.0}}, torch::kFloat64);
  CHECK((w - want).abs().max().item<double>() < 1e-6);
  CHECK((w.sum(0) - 1.0).abs().max().item<double>() < 1e-6);
  CHECK_THROWS_AS(model::inverse_depth_layer_weights(d, {1.0, 1.0}), InputError);
  CHECK_THROWS_AS(model::inverse_depth_layer_weights(d, {}), InputError);
  CHECK_THROWS_AS(model::inverse_depth_layer_weights(torch::zeros({1, 1, 2, 2}), layers), InputError);
}

TEST_CASE("spectral Wiener: the unobserved part of a correction is (I - W Hbar) delta, keeps what the image cannot see and drops what it fixes",
          "[spectral_wiener]") {
  torch::manual_seed(31);
  const int64_t L = 5, K = 3;
  const torch::Tensor p = test::random_band_psfs(L, K, 7, 0.05);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), test::random_spd(L, 0.01), 1e-4};
  const torch::Tensor delta = torch::randn({2, L, 10, 13}, torch::kFloat64);
  const model::SpectralWienerFilter w = model::spectral_wiener_filter(model::spectral_otf(p, 10, 13), omega, prior);
  const torch::Tensor got = model::spectral_wiener_unobserved(w, delta);
  const torch::Tensor want = reference_unobserved(delta, p, omega, prior);
  REQUIRE(got.sizes() == delta.sizes());
  CHECK((got - want).abs().max().item<double>() < 1e-10 * want.abs().max().item<double>());
  // It is not the identity, and float32 corrections come back in float32.
  CHECK((got - delta).abs().max().item<double>() > 1e-2 * delta.abs().max().item<double>());
  const torch::Tensor got32 = model::spectral_wiener_unobserved(w, delta.to(torch::kFloat32));
  CHECK(got32.scalar_type() == torch::kFloat32);
  CHECK((got32.to(torch::kFloat64) - want).abs().max().item<double>() < 1e-5 * want.abs().max().item<double>());
  CHECK_THROWS_AS(model::spectral_wiener_unobserved(w, delta.narrow(1, 0, L - 1)), InputError);

  // Without blur, a correction in Ω's null space makes no image: it passes untouched.
  const torch::Tensor flat = delta_psfs(L, K, 7, torch::kFloat64);
  const model::SpectralWienerFilter w0 = model::spectral_wiener_filter(model::spectral_otf(flat, 10, 13), omega, prior);
  const torch::Tensor U = std::get<2>(torch::linalg_svd(omega, true));  // rows 3.. span Ω's null space
  const torch::Tensor v = U.select(0, L - 1);                            // [L], Ω v = 0
  REQUIRE(torch::matmul(omega, v).abs().max().item<double>() < 1e-12);
  const torch::Tensor null_delta = v.view({1, L, 1, 1}) * torch::randn({1, 1, 10, 13}, torch::kFloat64);
  CHECK((model::spectral_wiener_unobserved(w0, null_delta) - null_delta).abs().max().item<double>() < 1e-12);

  // A sharp, invertible camera with almost no noise sees every correction: nothing is left.
  const int64_t L3 = 3;
  const torch::Tensor om3 = torch::eye(3, torch::kFloat64) + 0.2 * torch::rand({3, 3}, torch::kFloat64);
  const model::SpectralPrior p3{torch::rand({L3}, torch::kFloat64), test::random_spd(L3, 0.01), 1e-12};
  const model::SpectralWienerFilter w3 =
      model::spectral_wiener_filter(model::spectral_otf(delta_psfs(L3, 2, 5, torch::kFloat64), 9, 11), om3, p3);
  const torch::Tensor d3 = torch::randn({1, L3, 9, 11}, torch::kFloat64);
  CHECK(model::spectral_wiener_unobserved(w3, d3).abs().max().item<double>() < 1e-6 * d3.abs().max().item<double>());
}

TEST_CASE("spectral Wiener: the unobserved part's gradients in the correction and the PSFs match central differences (float64)",
          "[spectral_wiener]") {
  torch::manual_seed(15);
  const int64_t L = 4;
  const torch::Tensor d = torch::randn({1, L, 9, 11}, torch::kFloat64);
  const torch::Tensor p = torch::rand({L, 2, 5, 5}, torch::kFloat64) + 0.1;
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), test::random_spd(L, 0.01), 1e-3};
  const torch::Tensor wt = torch::randn({1, L, 9, 11}, torch::kFloat64);
  auto f = [&](const torch::Tensor& dd, const torch::Tensor& pp) {
    const torch::Tensor pn = pp / pp.sum({2, 3}, true);
    const auto w = model::spectral_wiener_filter(model::spectral_otf(pn, 9, 11), omega, prior);
    return (model::spectral_wiener_unobserved(w, dd) * wt).sum();
  };
  for (const auto& g : test::image_psf_gradient_check(f, d, p, 1e-4)) {
    INFO(g.input << " entry " << g.entry);
    CHECK(g.autograd == Approx(g.difference).epsilon(1e-5).margin(1e-9));
  }
}

TEST_CASE("spectral Wiener: model.project_residual adds the head's residual through (I - W Hbar), and is refused without the spectral Wiener base",
          "[spectral_wiener]") {
  torch::manual_seed(41);
  // A sharp, invertible 3-band camera with almost no noise: the image fixes
  // every cube, so a projected residual is nothing, whatever the weights.
  const int64_t L = 3;
  model::NetOptions o;
  o.bands = L, o.base_width = 4, o.levels = 1, o.norm = NormKind::group, o.residual_spectral_wiener = true;
  const torch::Tensor Om = torch::eye(3) + 0.2 * torch::rand({3, 3});
  const torch::Tensor sig = test::random_spd(L, 1e-2).to(torch::kFloat32);
  auto make = [&](bool project) {
    model::NetOptions oo = o;
    oo.project_residual = project;
    torch::manual_seed(7);  // the same weights for both
    model::HsdNet net(oo, torch::rand({L, 3}));
    net->set_spectral_prior(torch::rand({L}) * 0.3, sig, 1e-12, Om);
    net->set_band_psf(delta_psfs(L, 2, 5, torch::kFloat32));
    net->eval();
    return net;
  };
  model::HsdNet plain = make(false), projected = make(true);
  const torch::Tensor x = torch::rand({2, 3, 12, 16});
  torch::NoGradGuard ng;
  const torch::Tensor base = plain->spectral_wiener(x);
  const double moved = (plain->forward(x).hs - base).abs().max().item<double>();
  REQUIRE(moved > 1e-3);  // the unprojected random head changes the cube
  CHECK((projected->forward(x).hs - base).abs().max().item<double>() < 1e-4 * moved);
  // Blurred bands: the projection keeps part of the residual, and its filter is kept between calls.
  model::HsdNet blurred = make(true);
  blurred->set_band_psf(test::random_band_psfs(L, 2, 5, 0.05).to(torch::kFloat32));
  const torch::Tensor a = blurred->forward(x).hs, b = blurred->forward(x).hs;
  CHECK(a.equal(b));
  CHECK((a - blurred->spectral_wiener(x)).abs().max().item<double>() > 1e-4 * moved);
  // No TorchScript form: the export refuses it with one clear line.
  const model::ExportMetadata meta{{450e-9, 550e-9, 650e-9}, {{"camera", "test"}}, {}};
  CHECK_THROWS_WITH(model::export_torchscript(projected, meta), Catch::Contains("project_residual"));
  // The config refuses it without the base it projects onto, naming the key.
  CHECK_THROWS_WITH(load_config(test::source_path("configs/tiny.json"), {"model.project_residual=true", "model.residual=\"image\""}),
                    Catch::Contains("project_residual"));
}
