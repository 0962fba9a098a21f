// The illuminant reader (model/illuminant_reader.h): equal weights give back
// the training prior of data::radiance_moments; the reflectance's moments by
// hand; the log-likelihood against its definition summed block by block; the
// light of images drawn from the model read correctly for every illuminant of
// a bank and at intensities the profile must find; the tempering's limits;
// the posterior mixture by hand; the network's base under each image's
// posterior in eval mode only; the config's keys; bad input.
#include <catch2/catch.hpp>

#include <torch/torch.h>

#include <cmath>

#include "common/config.h"
#include "common/error.h"
#include "data/spectral_moments.h"
#include "helpers.h"
#include "model/illuminant_reader.h"
#include "model/net_options.h"
#include "model/unet.h"

using namespace hsd;

namespace {

const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);

// Four illuminants over 6 bands, unlike one another: flat, warm (rising),
// cool (falling) and spiky (two narrow lines).
torch::Tensor bank() {
  return torch::tensor({1.0, 1.0, 1.0, 1.0, 1.0, 1.0,   //
                        0.2, 0.35, 0.5, 0.7, 0.85, 1.0,  //
                        1.0, 0.85, 0.7, 0.5, 0.35, 0.2,  //
                        0.1, 1.0, 0.1, 0.1, 0.9, 0.1},
                       f64)
      .view({4, 6});
}

// A camera response [3, 6]: blue, green, red over the six bands.
torch::Tensor omega() {
  return torch::tensor({0.6, 0.4, 0.1, 0.0, 0.0, 0.0,  //
                        0.0, 0.2, 0.5, 0.5, 0.2, 0.0,  //
                        0.0, 0.0, 0.0, 0.1, 0.4, 0.6},
                       f64)
      .view({3, 6});
}

// Reflectance scene [6, H, W]: blocks of side `blk`, each a random mix of two
// smooth basis spectra plus a little of a third (as natural reflectances).
data::LoadedScene reflectance_scene(int64_t H, int64_t W, int64_t blk, uint64_t seed) {
  torch::manual_seed(seed);
  const torch::Tensor lam = torch::linspace(0, 1, 6, f64);
  const torch::Tensor basis = torch::stack({torch::ones_like(lam), lam, (lam - 0.5).pow(2)});  // [3, 6]
  const int64_t nb = (H / blk) * (W / blk);
  const torch::Tensor c = torch::stack({0.2 + 0.4 * torch::rand({nb}, f64), 0.3 * (torch::rand({nb}, f64) - 0.5),
                                        0.4 * (torch::rand({nb}, f64) - 0.5)},
                                       1);                                          // [nb, 3]
  torch::Tensor r = torch::matmul(c, basis).clamp(0.01, 1.0);                       // [nb, 6]
  r = r.t().reshape({6, H / blk, W / blk});
  r = r.repeat_interleave(blk, 1).repeat_interleave(blk, 2);
  data::LoadedScene s;
  s.file = "drawn.exr";
  s.scene.spectral = r.to(torch::kFloat32);
  s.scene.depth_m = torch::ones({1, H, W});
  s.scene.mask = torch::ones({1, H, W});
  return s;
}

}  // namespace

TEST_CASE("illuminant reader: equal weights give the training prior, and the reflectance moments by hand",
          "[illuminant_reader]") {
  const data::LoadedScene s = reflectance_scene(32, 48, 4, 3);
  const torch::Tensor E = bank();
  const data::SpectralMoments train = data::radiance_moments({s}, E, 0.6, 1.4);
  const data::ReflectanceMoments r = data::reflectance_moments({s});
  CHECK(r.pixels == 32 * 48);
  const torch::Tensor x = s.scene.spectral.reshape({6, -1}).to(torch::kFloat64);
  CHECK(torch::allclose(r.mean, x.mean(1), 1e-12, 1e-14));
  CHECK(torch::allclose(r.second, torch::matmul(x, x.t()) / double(x.size(1)), 1e-12, 1e-14));
  const model::IlluminantMoments m = model::illuminant_moments(r.mean, r.second, E, 0.6, 1.4);
  const model::SpectralPrior p = model::illuminant_mixture_prior(m, torch::full({4}, 0.25, f64), 1e-5);
  CHECK(torch::allclose(p.mean, train.mean, 1e-10, 1e-14));
  CHECK(torch::allclose(p.covariance, train.covariance, 1e-10, 1e-14));
  CHECK(p.noise_var == 1e-5);
  // One illuminant's weight: its own moments, E[s] e ⊙ m_r and E[s²] diag(e) R_r diag(e) − μ μᵀ.
  const torch::Tensor w = torch::tensor({0.0, 0.0, 1.0, 0.0}, f64);
  const model::SpectralPrior q = model::illuminant_mixture_prior(m, w, 1e-5);
  const double es = 1.0, es2 = (0.36 + 0.84 + 1.96) / 3.0;
  const torch::Tensor mu = es * E[2] * r.mean;
  CHECK(torch::allclose(q.mean, mu, 1e-12, 1e-14));
  CHECK(torch::allclose(q.covariance, es2 * torch::outer(E[2], E[2]) * r.second - torch::outer(mu, mu), 1e-10, 1e-14));
  // A radiance scene cannot be split into reflectance and light.
  data::LoadedScene rad = s;
  rad.scene.kind = data::SpectralKind::Radiance;
  CHECK_THROWS_AS(data::reflectance_moments({rad}), InputError);
}

TEST_CASE("illuminant reader: the log-likelihood against its definition block by block", "[illuminant_reader]") {
  const data::LoadedScene s = reflectance_scene(24, 40, 8, 5);
  const data::ReflectanceMoments r = data::reflectance_moments({s});
  const model::IlluminantMoments m = model::illuminant_moments(r.mean, r.second, bank(), 0.5, 1.5);
  const torch::Tensor Om = omega(), kappa = torch::tensor({0.9, 0.8, 1.0, 1.0, 0.7, 0.6}, f64);
  torch::manual_seed(9);
  const torch::Tensor img = 0.3 + 0.2 * torch::rand({1, 3, 24, 40}, f64);  // 3 × 5 blocks of 8
  const double sigma2 = 2e-4;
  const torch::Tensor ll = model::illuminant_log_likelihood(img, Om, kappa, m, sigma2, 8);
  REQUIRE(ll.sizes() == torch::IntArrayRef{1, 4});
  // By hand: for each k the maximum over the same intensity grid of Σ_j log N(b_j; s g, s² A + τ² I)
  // (without the constant −(3/2) log 2π per block, which the code leaves out too).
  const torch::Tensor b = torch::nn::functional::avg_pool2d(img, torch::nn::functional::AvgPool2dFuncOptions(8))
                              .flatten(2)[0]
                              .t();  // [15, 3]
  const double tau2 = sigma2 / 64.0 + 1e-4 * (b * b).mean().item<double>();
  const torch::Tensor G = Om * kappa.view({1, 6});
  const torch::Tensor grid = torch::logspace(std::log10(0.25), std::log10(3.0), 49, 10.0, f64);
  for (int64_t k = 0; k < 4; ++k) {
    const torch::Tensor mu = m.mean[k], C = m.second[k] - torch::outer(mu, mu);
    const torch::Tensor g = torch::matmul(G, mu), A = torch::matmul(torch::matmul(G, C), G.t());
    double best = -1e300;
    for (int64_t i = 0; i < grid.size(0); ++i) {
      const double sv = grid[i].item<double>();
      const torch::Tensor S = sv * sv * A + tau2 * torch::eye(3, f64);
      const torch::Tensor Si = torch::inverse(S);
      const double ld = torch::logdet(S).item<double>();
      double sum = 0;
      for (int64_t j = 0; j < b.size(0); ++j) {
        const torch::Tensor d = b[j] - sv * g;
        sum += -0.5 * (ld + torch::dot(d, torch::mv(Si, d)).item<double>());
      }
      best = std::max(best, sum);
    }
    INFO("illuminant " << k);
    CHECK(ll[0][k].item<double>() == Approx(best).epsilon(1e-9));
  }
}

TEST_CASE("illuminant reader: the light of drawn scenes is read for every illuminant and intensity",
          "[illuminant_reader]") {
  // Training reflectances and test reflectances are drawn alike but are different scenes.
  const data::ReflectanceMoments r = data::reflectance_moments({reflectance_scene(64, 64, 4, 1)});
  const torch::Tensor E = bank(), Om = omega(), kappa = torch::ones({6}, f64);
  const model::IlluminantMoments m = model::illuminant_moments(r.mean, r.second, E, 0.5, 1.5);
  const model::IlluminantReaderSettings st{16, 16};
  for (const double s : {0.3, 1.0, 2.5}) {  // below, inside and above the training range
    for (int64_t k = 0; k < 4; ++k) {
      const data::LoadedScene test = reflectance_scene(96, 128, 8, 100 + uint64_t(k));
      const torch::Tensor rad = s * test.scene.spectral.to(torch::kFloat64) * E[k].view({6, 1, 1});
      torch::Tensor img = torch::einsum("cl,lhw->chw", {Om, rad}).unsqueeze(0);
      img = img + 1e-3 * torch::randn_like(img);
      const torch::Tensor ll = model::illuminant_log_likelihood(img, Om, kappa, m, 1e-6, st.block_px);
      const torch::Tensor w = model::illuminant_posterior(ll, 96, 128, st);
      INFO("illuminant " << k << ", intensity " << s << ", posterior " << w);
      CHECK(w[0].argmax().item<int64_t>() == k);
      CHECK(w[0][k].item<double>() > 0.9);
      CHECK(w.sum().item<double>() == Approx(1.0).epsilon(1e-12));
    }
  }
}

TEST_CASE("illuminant reader: the tempering's limits and bad input", "[illuminant_reader]") {
  const torch::Tensor ll = torch::tensor({-10.0, -12.0, -30.0}, f64).view({1, 3});
  // effective_blocks → 0: equal weights; = J: the untempered posterior.
  const torch::Tensor w0 = model::illuminant_posterior(ll, 64, 64, {16, 1e-9});
  CHECK(torch::allclose(w0, torch::full({1, 3}, 1.0 / 3.0, f64), 1e-8, 1e-10));
  const torch::Tensor w1 = model::illuminant_posterior(ll, 64, 64, {16, 16});
  CHECK(torch::allclose(w1, torch::softmax(ll, 1), 1e-12, 1e-14));
  CHECK_THROWS_AS(model::illuminant_posterior(ll, 64, 64, {16, 0}), InputError);
  const data::ReflectanceMoments r = data::reflectance_moments({reflectance_scene(16, 16, 4, 2)});
  const model::IlluminantMoments m = model::illuminant_moments(r.mean, r.second, bank(), 0.5, 1.5);
  CHECK_THROWS_AS(model::illuminant_log_likelihood(torch::ones({1, 4, 8, 8}, f64), omega(), torch::ones({6}, f64), m, 1e-6, 4),
                  InputError);
  CHECK_THROWS_AS(model::illuminant_log_likelihood(torch::ones({1, 3, 8, 8}, f64), omega(), torch::ones({5}, f64), m, 1e-6, 4),
                  InputError);
  CHECK_THROWS_AS(model::illuminant_log_likelihood(torch::ones({1, 3, 8, 8}, f64), omega(), torch::ones({6}, f64), m, 0.0, 4),
                  InputError);
  CHECK_THROWS_AS(model::illuminant_moments(r.mean, r.second, torch::ones({2, 5}, f64), 0.5, 1.5), InputError);
  CHECK_THROWS_AS(model::illuminant_mixture_prior(m, torch::ones({3}, f64), 1e-6), InputError);
  torch::Tensor bad = torch::ones({1, 3, 8, 8}, f64);
  bad[0][1][2][2] = std::nan("");
  CHECK_THROWS_AS(model::illuminant_log_likelihood(bad, omega(), torch::ones({6}, f64), m, 1e-6, 4), NumericalError);
}

TEST_CASE("illuminant reader: the network's base uses each image's posterior prior in eval mode, the buffers' in training",
          "[illuminant_reader]") {
  torch::manual_seed(4);
  model::NetOptions o;
  o.bands = 6, o.base_width = 4, o.levels = 1, o.norm = NormKind::group, o.residual_spectral_wiener = true;
  o.read_illuminant = true, o.illuminant_reader = {8, 16}, o.layer_depths_m = {0.6, 1.8};
  model::HsdNet net(o, torch::rand({6, 3}));
  const data::ReflectanceMoments r = data::reflectance_moments({reflectance_scene(64, 64, 4, 1)});
  const torch::Tensor E = bank(), Om = omega();
  const model::IlluminantMoments m = model::illuminant_moments(r.mean, r.second, E, 0.5, 1.5);
  const model::SpectralPrior eq = model::illuminant_mixture_prior(m, torch::full({4}, 0.25, f64), 1e-6);
  net->set_spectral_prior(eq.mean.to(torch::kFloat32), eq.covariance.to(torch::kFloat32), 1e-6, Om.to(torch::kFloat32));
  net->set_illuminant_moments(m);
  torch::Tensor psf = torch::rand({6, 2, 9, 9});
  net->set_band_psf(psf / psf.sum({2, 3}, true));
  // Two scenes, lit by the warm and the spiky light.
  std::vector<torch::Tensor> imgs;
  for (const int64_t k : {1, 3}) {
    const data::LoadedScene sc = reflectance_scene(48, 64, 8, 50 + uint64_t(k));
    imgs.push_back(torch::einsum("cl,lhw->chw", {Om, sc.scene.spectral.to(torch::kFloat64) * E[k].view({6, 1, 1})}));
  }
  const torch::Tensor x = torch::stack(imgs).to(torch::kFloat32);
  torch::NoGradGuard ng;
  net->eval();
  const torch::Tensor base = net->spectral_wiener(x);
  for (int k = 0; k < 2; ++k) CHECK(net->spectral_wiener(x).equal(base));  // the OTFs kept: bitwise the same
  const torch::Tensor w = net->illuminant_posterior(x);
  CHECK(w[0].argmax().item<int64_t>() == 1);
  CHECK(w[1].argmax().item<int64_t>() == 3);
  const torch::Tensor band_psf = net->band_psf();
  for (int64_t b = 0; b < 2; ++b) {
    const torch::Tensor xb = x.narrow(0, b, 1);
    const torch::Tensor want =
        model::spectral_wiener_cube(xb, band_psf, Om.to(torch::kFloat32), model::illuminant_mixture_prior(m, w[b], 1e-6));
    INFO("image " << b << ": largest difference " << (base.narrow(0, b, 1) - want).abs().max().item<double>() << " of " << want.abs().max().item<double>());
    CHECK((base.narrow(0, b, 1) - want).abs().max().item<double>() <= 1e-6 * want.abs().max().item<double>());
  }
  const torch::Tensor equal = model::spectral_wiener_cube(x, band_psf, Om.to(torch::kFloat32), net->spectral_prior()).to(torch::kFloat32);
  CHECK((base - equal).abs().max().item<double>() > 1e-3 * equal.abs().max().item<double>());  // the read light matters
  net->train();
  CHECK((net->spectral_wiener(x) - equal).abs().max().item<double>() <= 1e-6 * equal.abs().max().item<double>());  // training keeps the equal weights
}

TEST_CASE("illuminant reader: the config's keys are read, checked and refused where they cannot apply",
          "[illuminant_reader][config]") {
  const Config q = load_config(test::source_path("configs/quick.json"),
                               {"model.read_illuminant=true", "model.illuminant_block_px=8",
                                "model.illuminant_effective_blocks=4"});
  const model::NetOptions o = model::net_options(q);
  CHECK(o.read_illuminant);
  CHECK(o.illuminant_reader.block_px == 8);
  CHECK(o.illuminant_reader.effective_blocks == 4.0);
  CHECK_THROWS_WITH(load_config(test::source_path("configs/tiny.json"), {"model.read_illuminant=true"}),
                    Catch::Contains("read_illuminant"));
  CHECK_THROWS_WITH(load_config(test::source_path("configs/quick.json"), {"model.illuminant_block_px=0"}),
                    Catch::Contains("illuminant_block_px"));
  CHECK_THROWS_WITH(load_config(test::source_path("configs/quick.json"), {"model.illuminant_effective_blocks=0"}),
                    Catch::Contains("illuminant_effective_blocks"));
}
