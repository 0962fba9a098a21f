// The spectral Wiener cube with an edge prior (model/spectral_tv.h): weight 0
// is the spectral Wiener cube; every x-step of the splitting is exact (one
// layer or three), so a vanishing weight keeps the Wiener cube as its fixed point; on a
// piecewise-constant scene behind chromatic blur and noise the prior lowers
// both the error and the total variation; bad settings and shapes are
// InputErrors; the network's base uses it in eval mode only, and the export
// refuses it.
#include <catch2/catch.hpp>

#include <torch/torch.h>

#include "common/config.h"
#include "common/error.h"
#include "helpers.h"
#include "model/net_options.h"
#include "model/spectral_tv.h"
#include "model/spectral_wiener.h"
#include "model/torchscript_export.h"
#include "model/unet.h"

using namespace hsd;

namespace {

// Normalised Gaussian PSFs [L, 1, P, P], band l of width sigmas[l] px.
torch::Tensor gaussian_psfs(const std::vector<double>& sigmas, int64_t P) {
  const int64_t L = int64_t(sigmas.size()), r = P / 2;
  const torch::Tensor t = torch::arange(-r, r + 1, torch::kFloat64);
  const torch::Tensor d2 = t.view({-1, 1}).square() + t.view({1, -1}).square();
  std::vector<torch::Tensor> out;
  for (int64_t l = 0; l < L; ++l) {
    const torch::Tensor g = torch::exp(-d2 / (2 * sigmas[size_t(l)] * sigmas[size_t(l)]));
    out.push_back(g / g.sum());
  }
  return torch::stack(out, 0).unsqueeze(1);
}

// Each band blurred by its layer-0 PSF (same-size, edge-replicated), then Ω.
torch::Tensor render(const torch::Tensor& cube, const torch::Tensor& psf, const torch::Tensor& omega) {
  namespace F = torch::nn::functional;
  const int64_t L = cube.size(1), r = psf.size(2) / 2;
  const torch::Tensor padded = F::pad(cube, F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate));
  const torch::Tensor k = psf.select(1, 0).flip({1, 2}).unsqueeze(1);  // [L, 1, P, P], convolution
  const torch::Tensor blurred = F::conv2d(padded, k, F::Conv2dFuncOptions().groups(L));
  return torch::einsum("cl,blhw->bchw", {omega, blurred});
}

}  // namespace

TEST_CASE("spectral TV: weight 0 is the spectral Wiener cube", "[spectral_tv]") {
  torch::manual_seed(3);
  const int64_t L = 5, K = 3;
  const torch::Tensor x = torch::rand({2, 3, 12, 15}, torch::kFloat64);
  const torch::Tensor p = test::random_band_psfs(L, K, 7, 0.05);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), test::random_spd(L, 0.01), 1e-4};
  const torch::Tensor want = model::spectral_wiener_cube(x, p, omega, prior);
  const torch::Tensor got = model::spectral_tv_cube(x, model::spectral_otf(p, 12, 15), omega, prior, {});
  CHECK((got - want).abs().max().item<double>() < 1e-10 * want.abs().max().item<double>());
}

TEST_CASE("spectral TV: the Wiener cube is the splitting's fixed point as the weight vanishes", "[spectral_tv]") {
  // With v = ∇x_W (no shrinkage) the x-step's minimiser is x_W itself: the
  // prior's shifted mean m = ρ C' Dᴴ V, the covariance C', the layers' spread
  // N and M must all be right for the cube to stay put while ρ grows
  // 2^9-fold, for one layer and for three. A weight that shrinks moves it.
  torch::manual_seed(8);
  const int64_t L = 6;
  const torch::Tensor x = torch::rand({1, 3, 16, 14}, torch::kFloat64);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), test::random_spd(L, 0.02), 1e-4};
  model::EdgePriorSettings s;
  s.weight = 1e-14, s.iterations = 10, s.rho_start = 1e-2, s.rho_factor = 2.0;
  for (int64_t K : {1, 3}) {
    const torch::Tensor p = test::random_band_psfs(L, K, 7, K == 1 ? 0.05 : 0.0);
    const model::SpectralOtf otf = model::spectral_otf(p, 16, 14);
    const torch::Tensor w = model::spectral_wiener_cube(x, p, omega, prior);
    const double scale = w.abs().max().item<double>();
    INFO(K << " layers");
    CHECK((model::spectral_tv_cube(x, otf, omega, prior, s) - w).abs().max().item<double>() < 1e-9 * scale);
    model::EdgePriorSettings moved = s;
    moved.weight = 1e-3;
    CHECK((model::spectral_tv_cube(x, otf, omega, prior, moved) - w).abs().max().item<double>() > 1e-4 * scale);
  }
}

TEST_CASE("spectral TV: a piecewise-constant scene behind chromatic blur and noise comes back sharper and closer",
          "[spectral_tv]") {
  // Two spectra (a disc on a background), 4 bands blurred 0.8-3 px, a random
  // camera, noise σ = 0.01. The prior: the two spectra's mean and
  // covariance (plus a little), as the training split would give.
  torch::manual_seed(12);
  const int64_t L = 4, H = 40, W = 44;
  const torch::Tensor a = torch::tensor({0.2, 0.5, 0.7, 0.4}, torch::kFloat64);
  const torch::Tensor b = torch::tensor({0.6, 0.3, 0.2, 0.5}, torch::kFloat64);
  const torch::Tensor yy = torch::arange(H, torch::kFloat64).view({-1, 1}), xx = torch::arange(W, torch::kFloat64).view({1, -1});
  const torch::Tensor disc = ((yy - 19.5).square() + (xx - 21.5).square() < 13.0 * 13.0).to(torch::kFloat64);  // [H, W]
  const torch::Tensor cube = (a.view({1, L, 1, 1}) * disc + b.view({1, L, 1, 1}) * (1.0 - disc)).contiguous();
  const torch::Tensor psf = gaussian_psfs({3.0, 1.5, 0.8, 2.2}, 15);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64) + 0.1;
  const double sigma = 0.01;
  const torch::Tensor y = render(cube, psf, omega) + sigma * torch::randn({1, 3, H, W}, torch::kFloat64);
  const torch::Tensor mean = 0.5 * (a + b), d = (a - b).view({-1, 1});
  const model::SpectralPrior prior{mean, 0.25 * torch::matmul(d, d.t()) + 1e-3 * torch::eye(L, torch::kFloat64),
                                   sigma * sigma};
  const torch::Tensor wiener = model::spectral_wiener_cube(y, psf, omega, prior);
  model::EdgePriorSettings s;
  s.weight = 1e-3, s.iterations = 10;
  const torch::Tensor tv = model::spectral_tv_cube(y, model::spectral_otf(psf, H, W), omega, prior, s);
  const double e_w = (wiener - cube).square().mean().sqrt().item<double>();
  const double e_tv = (tv - cube).square().mean().sqrt().item<double>();
  INFO("RMSE Wiener " << e_w << ", TV " << e_tv);
  CHECK(e_tv < 0.7 * e_w);
  const double tv_true = model::coupled_total_variation(cube).item<double>();
  const double tv_w = model::coupled_total_variation(wiener).item<double>();
  const double tv_tv = model::coupled_total_variation(tv).item<double>();
  INFO("total variation: truth " << tv_true << ", Wiener " << tv_w << ", TV " << tv_tv);
  CHECK(tv_tv < tv_w);
  CHECK(std::abs(tv_tv - tv_true) < std::abs(tv_w - tv_true));
  // float32 images give the same cube to float32 precision
  const torch::Tensor tv32 = model::spectral_tv_cube(y.to(torch::kFloat32), model::spectral_otf(psf, H, W), omega, prior, s);
  CHECK(tv32.scalar_type() == torch::kFloat32);
  CHECK((tv32.to(torch::kFloat64) - tv).abs().max().item<double>() < 1e-4);
}

TEST_CASE("spectral TV: bad settings, shapes and OTFs without layers are input errors", "[spectral_tv]") {
  const int64_t L = 3;
  const torch::Tensor x = torch::rand({1, 3, 8, 8}, torch::kFloat64);
  const torch::Tensor p = test::random_band_psfs(L, 2, 5, 0.1);
  const torch::Tensor omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior{torch::rand({L}, torch::kFloat64), test::random_spd(L, 0.01), 1e-4};
  const model::SpectralOtf otf = model::spectral_otf(p, 8, 8);
  auto with = [](double w, int64_t it, double r0, double rf) {
    model::EdgePriorSettings s;
    s.weight = w, s.iterations = it, s.rho_start = r0, s.rho_factor = rf;
    return s;
  };
  CHECK_THROWS_AS(model::spectral_tv_cube(x, otf, omega, prior, with(-1, 4, 1e-3, 2)), InputError);
  CHECK_THROWS_AS(model::spectral_tv_cube(x, otf, omega, prior, with(0.1, 0, 1e-3, 2)), InputError);
  CHECK_THROWS_AS(model::spectral_tv_cube(x, otf, omega, prior, with(0.1, 4, 0, 2)), InputError);
  CHECK_THROWS_AS(model::spectral_tv_cube(x, otf, omega, prior, with(0.1, 4, 1e-3, 1.0)), InputError);
  CHECK_THROWS_AS(model::spectral_tv_cube(torch::rand({1, 3, 8, 9}, torch::kFloat64), otf, omega, prior, {}), InputError);
  CHECK_THROWS_AS(model::spectral_tv_cube(x, otf, torch::rand({3, L + 1}, torch::kFloat64), prior, {}), InputError);
  model::SpectralOtf no_layers = otf;
  no_layers.Kf = torch::Tensor();
  CHECK_THROWS_AS(model::spectral_tv_cube(x, no_layers, omega, prior, {}), InputError);
}

TEST_CASE("spectral TV: the config's edge prior needs the spectral Wiener base and reaches the network",
          "[spectral_tv]") {
  const Config c = load_config(test::source_path("configs/quick.json"),
                               {"model.edge_prior_weight=0.003", "model.edge_prior_iterations=6"});
  const model::NetOptions o = model::net_options(c);
  CHECK(o.edge_prior.weight == Approx(0.003));
  CHECK(o.edge_prior.iterations == 6);
  std::string msg;
  try {
    load_config(test::source_path("configs/quick.json"),
                {"model.edge_prior_weight=0.003", "model.residual=\"image\"", "model.read_illuminant=false",
                 "model.fuse_defocus_reader=false"});
  } catch (const InputError& e) {
    msg = e.what();
  }
  CHECK(msg.find("edge_prior_weight") != std::string::npos);
}

TEST_CASE("spectral TV: the network's base uses the edge prior in eval mode only", "[spectral_tv]") {
  torch::manual_seed(4);
  const int64_t L = 4, K = 2;
  model::NetOptions o;
  o.bands = L, o.base_width = 4, o.levels = 1, o.norm = NormKind::group;
  o.residual_spectral_wiener = true;
  o.edge_prior.weight = 0.01, o.edge_prior.iterations = 4;
  const torch::Tensor omega = torch::rand({3, L}) + 0.1;
  model::HsdNet net(o, torch::rand({L, 3}));
  net->set_spectral_prior(torch::rand({L}), test::random_spd(L, 0.01).to(torch::kFloat32), 1e-4, omega);
  const torch::Tensor p = test::random_band_psfs(L, K, 5, 0.1).to(torch::kFloat32);
  net->set_band_psf(p);
  const torch::Tensor x = torch::rand({2, 3, 12, 12});
  const model::SpectralPrior prior = net->spectral_prior();
  const torch::Tensor wiener = model::spectral_wiener_cube(x, p, omega, prior);
  torch::NoGradGuard no_grad;
  net->train();
  CHECK((net->spectral_wiener(x) - wiener).abs().max().item<double>() < 1e-5);
  net->eval();
  const model::SpectralOtf otf = model::spectral_otf(p, 12, 12);
  const torch::Tensor want = torch::cat({model::spectral_tv_cube(x.narrow(0, 0, 1), otf, omega, prior, o.edge_prior),
                                         model::spectral_tv_cube(x.narrow(0, 1, 1), otf, omega, prior, o.edge_prior)});
  const torch::Tensor got = net->spectral_wiener(x);
  CHECK((got - want).abs().max().item<double>() < 1e-6);
  CHECK((got - wiener).abs().max().item<double>() > 1e-4);
  // no TorchScript form: the export refuses it with one clear line
  model::ExportMetadata meta{{450e-9, 500e-9, 550e-9, 600e-9}, {{"camera", "test"}}, {}};
  try {
    model::export_torchscript(net, meta);
    FAIL("exported a network with the edge prior");
  } catch (const InputError& e) {
    CHECK(std::string(e.what()).find("edge_prior_weight") != std::string::npos);
  }
}

