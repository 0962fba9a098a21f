// The classical depth-from-defocus cost volume (model/defocus_likelihood.h):
// the log-determinant term against a closed form (a delta PSF and a two-tap
// box, whose MTFs are 1 and cos²(π f_x)), the texture's scale profiled out,
// the layer that blurred a texture found, the depth map it reads, bad input,
// and the network's input with model.defocus_cost; the spectral reader
// against a full-grid DFT with 3x3 solves, its profiled scale, and a scene
// drawn from its prior read at the layer that imaged it; tied layers read at
// the mean of their depths.
#include <catch2/catch.hpp>

#include <torch/torch.h>

#include <array>
#include <cmath>
#include <vector>

#include "common/config.h"
#include "common/error.h"
#include "common/fft_size.h"
#include "helpers.h"
#include "model/defocus_likelihood.h"
#include "model/depth_fusion.h"
#include "model/net_options.h"
#include "model/unet.h"

using namespace hsd;
namespace F = torch::nn::functional;

namespace {

// mean over the n_h × n_w DFT grid of log(S(f) m(f) + ρ), S(f) = 1/(|f|² + f₀²)
// normalised to mean 1, m the MTF² — by loops over the frequencies.
double mean_log_det(int64_t nh, int64_t nw, double f0, double rho, double (*mtf2)(double fy, double fx)) {
  auto freq = [](int64_t k, int64_t n) { return double(k < (n + 1) / 2 ? k : k - n) / double(n); };
  double smean = 0;
  for (int64_t a = 0; a < nh; ++a)
    for (int64_t b = 0; b < nw; ++b) smean += 1.0 / (std::pow(freq(a, nh), 2) + std::pow(freq(b, nw), 2) + f0 * f0);
  smean /= double(nh * nw);
  double sum = 0;
  for (int64_t a = 0; a < nh; ++a)
    for (int64_t b = 0; b < nw; ++b) {
      const double fy = freq(a, nh), fx = freq(b, nw);
      const double S = 1.0 / (fy * fy + fx * fx + f0 * f0) / smean;
      sum += std::log(S * mtf2(fy, fx) + rho);
    }
  return sum / double(nh * nw);
}

// PSFs [2, 1, 3, 3]: layer 0 a delta, layer 1 a horizontal two-tap box (½, ½).
torch::Tensor delta_and_box() {
  torch::Tensor p = torch::zeros({2, 1, 3, 3}, torch::kFloat64);
  p[0][0][1][1] = 1.0;
  p[1][0][1][1] = 0.5, p[1][0][1][2] = 0.5;
  return p;
}

// Gaussian PSFs [K, 1, P, P] of widths sigma_px, each summing to 1.
torch::Tensor gaussians(const std::vector<double>& sigma_px, int64_t P) {
  const torch::Tensor t = torch::arange(P, torch::kFloat64) - double(P / 2);
  std::vector<torch::Tensor> out;
  for (double s : sigma_px) {
    const torch::Tensor g = torch::exp(-(t.view({-1, 1}).square() + t.view({1, -1}).square()) / (2 * s * s));
    out.push_back((g / g.sum()).unsqueeze(0));
  }
  return torch::stack(out);
}

}  // namespace

TEST_CASE("defocus likelihood: a uniform image's costs are its whitened level plus the closed-form log-determinants",
          "[defocus]") {
  const int64_t H = 14, W = 19;
  const model::DefocusModel m{0.05, 1.0 / 16, 5};
  const int64_t nh = fast_fft_size(H + 2), nw = fast_fft_size(W + 2);
  const double a = 0.37;
  const torch::Tensor cost = model::defocus_cost_volume(torch::full({1, 1, H, W}, a, torch::kFloat64), delta_and_box(), m);
  REQUIRE(cost.sizes() == c10::IntArrayRef{1, 2, H, W});
  const double ld0 = mean_log_det(nh, nw, m.corner_cycles_per_px, m.noise_ratio, [](double, double) { return 1.0; });
  const double ld1 = mean_log_det(nh, nw, m.corner_cycles_per_px, m.noise_ratio,
                                  [](double, double fx) { return std::pow(std::cos(M_PI * fx), 2); });
  // Only the zero frequency is present, where both MTFs are 1: w = a / √(S(0) + ρ) in both layers.
  double smean = 0;
  for (int64_t i = 0; i < nh; ++i)
    for (int64_t j = 0; j < nw; ++j) {
      const double fy = double(i < (nh + 1) / 2 ? i : i - nh) / nh, fx = double(j < (nw + 1) / 2 ? j : j - nw) / nw;
      smean += 1.0 / (fy * fy + fx * fx + m.corner_cycles_per_px * m.corner_cycles_per_px);
    }
  const double s0 = 1.0 / (m.corner_cycles_per_px * m.corner_cycles_per_px) / (smean / double(nh * nw));
  const double level = std::log(a * a / (s0 + m.noise_ratio));
  CHECK((cost[0][0] - (level + ld0)).abs().max().item<double>() < 1e-9);
  CHECK((cost[0][1] - (level + ld1)).abs().max().item<double>() < 1e-9);
  CHECK(ld1 < ld0);  // the box's MTF is below 1: a smaller determinant, so a textureless region prefers the blur
}

TEST_CASE("defocus likelihood: a brighter copy of the image shifts every layer's cost by the same 2 C log k", "[defocus]") {
  torch::manual_seed(3);
  const torch::Tensor y = torch::rand({2, 3, 20, 24}, torch::kFloat64);
  const torch::Tensor psf = gaussians({0.8, 2.0, 3.5}, 9).expand({3, 3, 9, 9});
  const model::DefocusModel m{0.01, 1.0 / 64, 7};
  const torch::Tensor d = model::defocus_cost_volume(4.0 * y, psf, m) - model::defocus_cost_volume(y, psf, m);
  CHECK((d - 3 * 2 * std::log(4.0)).abs().max().item<double>() < 1e-9);
}

TEST_CASE("defocus likelihood: the layer that blurred a texture has the least cost, and the depth map reads it",
          "[defocus]") {
  torch::manual_seed(11);
  const int64_t H = 64, W = 64, P = 15;
  const std::vector<double> sigma{0.6, 1.6, 3.2};
  const torch::Tensor psf = gaussians(sigma, P);
  // A texture with a natural image's falloff: white noise smoothed by a 3×3 box, plus a mean level.
  const torch::Tensor white = torch::randn({1, 1, H + 2 * P, W + 2 * P}, torch::kFloat64);
  const torch::Tensor tex = 1.0 + 0.3 * F::avg_pool2d(white, F::AvgPool2dFuncOptions(3).stride(1).padding(1));
  const model::DefocusModel m{1e-3, 1.0 / 64, 15};
  const std::vector<double> depths{0.5, 1.0, 2.0};
  for (size_t k = 0; k < sigma.size(); ++k) {
    // Blur the wider texture (a linear convolution), keep the middle H × W, add read noise.
    const torch::Tensor img = F::conv2d(tex, psf[int64_t(k)].unsqueeze(0).flip({-2, -1})).narrow(2, P / 2, H).narrow(3, P / 2, W) +
                              1e-4 * torch::randn({1, 1, H, W}, torch::kFloat64);
    const torch::Tensor cost = model::defocus_cost_volume(img, psf, m);
    const torch::Tensor right = (cost.argmin(1) == int64_t(k)).to(torch::kFloat64);
    INFO("layer " << k << " (sigma " << sigma[k] << " px)");
    // Away from the border, where the window sees only the image (not its edge-replicated extension).
    const int64_t e = P / 2 + m.window_px / 2;
    CHECK(right.narrow(1, e, H - 2 * e).narrow(2, e, W - 2 * e).mean().item<double>() > 0.95);
    CHECK(right.mean().item<double>() > 0.8);
    const torch::Tensor z = model::defocus_layer_depth(cost, depths);
    REQUIRE(z.sizes() == c10::IntArrayRef{1, H, W});
    CHECK(((z - depths[k]).abs() < 1e-12).to(torch::kFloat64).mean().item<double>() == Approx(right.mean().item<double>()));
  }
}

TEST_CASE("defocus likelihood: tied layers are read at the mean of their depths, not at the first", "[defocus]") {
  const std::vector<double> depths{0.5, 1.0, 2.0, 4.0};
  // Pixel by pixel: one least layer; all four tied (no cue); two tied; two within the tolerance; two just beyond it.
  const double t = model::kLayerTieNats;
  const torch::Tensor cost = torch::tensor({0.3, 0.1, 0.2, 0.4,   //
                                            0.7, 0.7, 0.7, 0.7,   //
                                            0.2, 0.5, 0.2, 0.9,   //
                                            0.5, 0.5 + 0.5 * t, 0.9, 0.9,  //
                                            0.5, 0.5 + 3.0 * t, 0.9, 0.9},
                                           torch::kFloat64)
                               .view({5, 4})
                               .t()
                               .reshape({1, 4, 1, 5});
  const torch::Tensor z = model::defocus_layer_depth(cost, depths);
  REQUIRE(z.sizes() == c10::IntArrayRef{1, 1, 5});
  CHECK(z[0][0][0].item<double>() == 1.0);
  CHECK(z[0][0][1].item<double>() == Approx(7.5 / 4).epsilon(1e-15));
  CHECK(z[0][0][2].item<double>() == Approx(1.25).epsilon(1e-15));
  CHECK(z[0][0][3].item<double>() == Approx(0.75).epsilon(1e-15));
  CHECK(z[0][0][4].item<double>() == 0.5);
  // float32 costs as the fused reader gives them: the same reading.
  const torch::Tensor z32 = model::defocus_layer_depth(cost.to(torch::kFloat32), depths);
  CHECK(z32.scalar_type() == torch::kFloat32);
  CHECK((z32.to(torch::kFloat64) - z).abs().max().item<double>() < 1e-6);
}

TEST_CASE("defocus likelihood: bad shapes and parameters are input errors", "[defocus]") {
  const torch::Tensor img = torch::rand({1, 3, 16, 16});
  const torch::Tensor psf = gaussians({1.0, 2.0}, 5).expand({2, 3, 5, 5}).to(torch::kFloat32);
  CHECK_THROWS_AS(model::defocus_cost_volume(img, psf.narrow(1, 0, 2), {}), InputError);  // 2 channels for 3
  CHECK_THROWS_AS(model::defocus_cost_volume(img, torch::rand({2, 3, 4, 4}), {}), InputError);  // even PSF
  CHECK_THROWS_AS(model::defocus_cost_volume(img, psf, model::DefocusModel{0.0, 1.0 / 64, 15}), InputError);
  CHECK_THROWS_AS(model::defocus_cost_volume(img, psf, model::DefocusModel{0.1, 1.0 / 64, 14}), InputError);
  CHECK_THROWS_AS(model::defocus_layer_depth(torch::rand({1, 2, 4, 4}), {0.5, 1.0, 2.0}), InputError);
  CHECK(torch::isfinite(model::defocus_cost_volume(torch::zeros({1, 3, 16, 16}), psf, {})).all().item<bool>());
}

TEST_CASE("defocus likelihood: model.defocus_cost puts the K-layer cost volume beside the network's inputs", "[defocus]") {
  torch::manual_seed(4);
  model::NetOptions o;
  o.bands = 5, o.base_width = 8, o.levels = 2, o.norm = NormKind::group, o.preinverse_layers = 2, o.layer_depths_m = {0.5, 1.0}, o.defocus_cost = DefocusCost::grey;
  model::HsdNet net(o, torch::rand({5, 3}));
  net->eval();
  net->set_preinverse_psf(gaussians({1.0, 2.5}, 7).expand({2, 3, 7, 7}).to(torch::kFloat32).contiguous());
  torch::NoGradGuard ng;
  const torch::Tensor x = torch::rand({1, 3, 20, 20});
  const model::NetOutput a = net->forward(x);
  CHECK(a.hs.sizes() == c10::IntArrayRef{1, 5, 20, 20});
  // The first block takes 3 (image) + 6 (pre-inversion) + 2 (cost) channels.
  bool found = false;
  for (const auto& p : net->named_parameters())
    if (p.key().rfind("down0.", 0) == 0 && p.value().dim() == 4) {
      CHECK(p.value().size(1) == 11);
      found = true;
      break;
    }
  CHECK(found);
  model::NetOptions bad = o;
  bad.preinverse_layers = 0;
  CHECK_THROWS(model::HsdNet(bad, torch::rand({5, 3})));
  CHECK_THROWS_WITH(load_config(test::source_path("configs/tiny.json"), {"model.defocus_cost=\"grey\""}),
                    Catch::Contains("defocus_cost"));
}

namespace {

// PSFs [L, K, P, P], positive, each slice summing to 1.
torch::Tensor random_psfs(int64_t L, int64_t K, int64_t P) {
  const torch::Tensor p = torch::rand({L, K, P, P}, torch::kFloat64) + 0.05;
  return p / p.sum({2, 3}, true);
}

model::SpectralPrior random_prior(int64_t L) {
  const torch::Tensor A = torch::rand({L, L}, torch::kFloat64);
  return {0.2 + 0.5 * torch::rand({L}, torch::kFloat64), A.matmul(A.t()) * 0.05 + 0.01 * torch::eye(L, torch::kFloat64), 1e-3};
}

}  // namespace

TEST_CASE("spectral defocus likelihood: the profiled Gaussian likelihood over the whole grid, by a full DFT and 3x3 solves",
          "[defocus]") {
  torch::manual_seed(21);
  const int64_t L = 4, K = 2, P = 3, H = 14, W = 14, N = 16;  // fast_fft_size(H + P - 1) = 16: the image fills the grid
  REQUIRE(fast_fft_size(H + P - 1) == N);
  const torch::Tensor psf = random_psfs(L, K, P), omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior = random_prior(L);
  const torch::Tensor img = torch::rand({1, 3, H, W}, torch::kFloat64);
  // A 33-px box covers the whole 16 x 16 grid from every pixel: one cost per layer.
  const torch::Tensor cost = model::spectral_defocus_cost_volume(img, psf, omega, prior, 33);
  REQUIRE(cost.sizes() == c10::IntArrayRef{1, K, H, W});
  // By hand: the image less Ω μ, edge-replicated by one pixel, its full DFT.
  const torch::Tensor y = F::pad(img - omega.matmul(prior.mean).view({1, 3, 1, 1}), F::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReplicate))[0];
  const torch::Tensor Y = torch::fft::fft2(y);  // [3, N, N]
  // S: (|f| + 1/N)^-2, normalised to mean 1 over the real half grid without DC, DC x 1e4.
  auto fr = [&](int64_t k) { return double(k < N / 2 ? k : k - N) / N; };
  double half = 0;
  for (int64_t a = 0; a < N; ++a)
    for (int64_t b = 0; b <= N / 2; ++b)
      if (a || b) half += std::pow(std::hypot(fr(a), double(b) / N) + 1.0 / N, -2.0);
  half /= double(N * (N / 2 + 1) - 1);
  for (int64_t k = 0; k < K; ++k) {
    // OTFs on the full grid with the PSF's centre at (0, 0).
    torch::Tensor placed = torch::zeros({L, N, N}, torch::kFloat64);
    for (int64_t i = 0; i < P; ++i)
      for (int64_t j = 0; j < P; ++j) placed.select(1, (i - 1 + N) % N).select(1, (j - 1 + N) % N).copy_(psf.select(1, k).select(1, i).select(1, j));
    const torch::Tensor Kf = torch::fft::fft2(placed);  // [L, N, N]
    double q = 0, ld = 0;
    for (int64_t a = 0; a < N; ++a)
      for (int64_t b = 0; b < N; ++b) {
        double S = std::pow(std::hypot(fr(a), fr(b)) + 1.0 / N, -2.0) / half;
        if (!a && !b) S = std::pow(1.0 / N, -2.0) / half * 1e4;
        const torch::Tensor Hm = omega.to(torch::kComplexDouble) * Kf.select(1, a).select(1, b).view({1, L});  // [3, L]
        const torch::Tensor M = S * Hm.matmul(prior.covariance.to(torch::kComplexDouble)).matmul(Hm.conj().t()) +
                                prior.noise_var * torch::eye(3, torch::kFloat64).to(torch::kComplexDouble);
        const torch::Tensor v = Y.select(1, a).select(1, b).view({3, 1});
        q += torch::real(v.conj().t().matmul(torch::linalg_solve(M, v, true))).item<double>();
        ld += std::get<1>(torch::linalg_slogdet(M)).item<double>();
      }
    // Parseval: Σ_x |w(x)|² = (1/N²) Σ_f |W(f)|², and the box mean divides by N² pixels.
    const double expect = 3.0 * std::log(q / double(N * N) / double(N * N) / 3.0) + ld / double(N * N);
    INFO("layer " << k);
    CHECK((cost[0][k] - expect).abs().max().item<double>() < 1e-8 * std::max(1.0, std::abs(expect)));
  }
}

TEST_CASE("spectral defocus likelihood: scaling the image's departure from the prior's mean shifts every layer by 6 log a",
          "[defocus]") {
  torch::manual_seed(22);
  const int64_t L = 5;
  const torch::Tensor psf = random_psfs(L, 3, 7), omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior = random_prior(L);
  const torch::Tensor mean_img = omega.matmul(prior.mean).view({1, 3, 1, 1});
  const torch::Tensor img = mean_img + 0.1 * torch::randn({2, 3, 18, 21}, torch::kFloat64);
  const torch::Tensor d = model::spectral_defocus_cost_volume(mean_img + 2.5 * (img - mean_img), psf, omega, prior, 9) -
                          model::spectral_defocus_cost_volume(img, psf, omega, prior, 9);
  CHECK((d - 6.0 * std::log(2.5)).abs().max().item<double>() < 1e-9);
  CHECK_THROWS_AS(model::spectral_defocus_cost_volume(img, psf, omega, prior, 8), InputError);
  CHECK_THROWS_AS(model::spectral_defocus_cost_volume(img, psf, omega.narrow(1, 0, 4), prior, 9), InputError);
}

TEST_CASE("spectral defocus likelihood: a scene drawn from the prior and imaged through one layer's band PSFs is read at that layer",
          "[defocus]") {
  torch::manual_seed(23);
  const int64_t L = 3, H = 64, W = 64, P = 15, E = H + 2 * P;
  // Chromatic defocus: each band's blur width moves with the layer, in a different direction per band.
  const std::vector<std::vector<double>> sigma{{0.6, 1.5, 3.0}, {1.5, 0.6, 1.5}, {3.0, 1.5, 0.6}};  // [band][layer]
  std::vector<torch::Tensor> bands;
  for (int64_t l = 0; l < L; ++l) bands.push_back(gaussians(sigma[size_t(l)], P).select(1, 0));  // [K, P, P]
  const torch::Tensor psf = torch::stack(bands);  // [L, K, P, P]
  const torch::Tensor omega = torch::tensor({0.8, 0.2, 0.0, 0.1, 0.8, 0.1, 0.0, 0.2, 0.8}, torch::kFloat64).view({3, 3});
  const model::SpectralPrior prior = random_prior(L);
  // A texture per spectral component, with a natural image's falloff, coloured by Σ^1/2 around μ.
  const torch::Tensor z = torch::randn({1, L, E, E}, torch::kFloat64);
  torch::Tensor zt = F::avg_pool2d(z, F::AvgPool2dFuncOptions(3).stride(1).padding(1));
  zt = zt / zt.std();
  const auto eig = torch::linalg_eigh(prior.covariance);
  const torch::Tensor root = std::get<1>(eig).matmul(torch::diag(std::get<0>(eig).clamp_min(0).sqrt()));
  const torch::Tensor x = prior.mean.view({1, L, 1, 1}) + torch::einsum("lm,bmhw->blhw", {root, zt});
  for (int64_t k = 0; k < 3; ++k) {
    // Each band through its layer-k PSF (a linear convolution), then the camera's mixing and read noise.
    const torch::Tensor kern = psf.select(1, k).unsqueeze(1).flip({-2, -1});  // [L, 1, P, P]
    const torch::Tensor blurred =
        F::conv2d(x, kern, F::Conv2dFuncOptions().groups(L)).narrow(2, P / 2, H).narrow(3, P / 2, W);
    const torch::Tensor img = torch::einsum("cl,blhw->bchw", {omega, blurred}) + 1e-3 * torch::randn({1, 3, H, W}, torch::kFloat64);
    const torch::Tensor cost = model::spectral_defocus_cost_volume(img, psf, omega, prior, 15);
    const torch::Tensor right = (cost.argmin(1) == k).to(torch::kFloat64);
    const int64_t e = P / 2 + 7;
    INFO("layer " << k);
    CHECK(right.narrow(1, e, H - 2 * e).narrow(2, e, W - 2 * e).mean().item<double>() > 0.9);
  }
}

TEST_CASE("defocus likelihood: model.fuse_defocus_reader fuses the head's depth with the spectral reader's in eval mode only",
          "[defocus]") {
  torch::manual_seed(24);
  model::NetOptions o;
  o.bands = 4, o.base_width = 8, o.levels = 2, o.norm = NormKind::group, o.residual_spectral_wiener = true;
  o.fuse_defocus_reader = true, o.layer_depths_m = {0.5, 2.0}, o.depth_min_m = 0.4, o.depth_max_m = 2.5;
  model::HsdNet net(o, torch::rand({4, 3}));
  const torch::Tensor a = torch::rand({4, 4});
  net->set_spectral_prior(torch::rand({4}) * 0.3, 1e-3 * (torch::matmul(a, a.t()) + 0.1 * torch::eye(4)), 1e-5,
                          torch::rand({3, 4}));
  torch::Tensor psf = torch::rand({4, 2, 9, 9});
  net->set_band_psf(psf / psf.sum({2, 3}, true));
  torch::NoGradGuard ng;
  const torch::Tensor x = torch::rand({2, 3, 24, 20});
  auto head_depth = [&](const model::NetOutput& out) {
    return 1.0 / (1.0 / o.depth_max_m + out.depth_unit * (1.0 / o.depth_min_m - 1.0 / o.depth_max_m));
  };
  net->eval();
  const model::NetOutput e = net->forward(x);
  const torch::Tensor guide = model::fusion_guide(e.hs);
  const torch::Tensor reader = net->reader_depth(x, guide);
  REQUIRE(reader.sizes() == c10::IntArrayRef{2, 1, 24, 20});
  CHECK(((reader == 0.5) | (reader == 2.0)).all().item<bool>());
  CHECK((e.depth_m - model::fuse_depths(head_depth(e), reader, guide, o.depth_min_m, o.depth_max_m)).abs().max().item<double>() <
        1e-6);
  // The reader's costs given (as the trainer gives a window's, cropped) or computed: the same depth.
  const torch::Tensor rc = net->fusion_reader_cost(x);
  REQUIRE(rc.sizes() == c10::IntArrayRef{2, 2, 24, 20});
  CHECK((rc.mean(1)).abs().max().item<double>() < 1e-4);  // less its mean over the layers
  CHECK(torch::equal(net->forward(x, {}, {}, rc).depth_m, e.depth_m));
  // The two readings alone, for the evaluation's report: the head's and the reader's.
  CHECK((e.network_depth_m - head_depth(e)).abs().max().item<double>() < 1e-6);
  CHECK(torch::equal(e.reader_depth_m, reader));
  CHECK_THROWS(net->forward(x, {}, {}, rc.narrow(3, 0, 10)));
  // Not the plain mean: the filter moves the average somewhere.
  CHECK((e.depth_m - 0.5 * (head_depth(e) + reader)).abs().max().item<double>() > 1e-3);
  CHECK((e.inv_depth * e.depth_m - 1.0).abs().max().item<double>() < 1e-6);
  net->train();
  const model::NetOutput t = net->forward(x);
  CHECK((t.depth_m - head_depth(t)).abs().max().item<double>() < 1e-6);
  CHECK(!t.network_depth_m.defined());
  CHECK(!t.reader_depth_m.defined());
  model::NetOptions bad = o;
  bad.layer_depths_m.clear();
  CHECK_THROWS(model::HsdNet(bad, torch::rand({4, 3})));
  CHECK_THROWS_WITH(load_config(test::source_path("configs/tiny.json"), {"model.fuse_defocus_reader=true"}),
                    Catch::Contains("fuse_defocus_reader"));
  // The fusion's settings: read from the config, checked, and {31, 0, 0} is the plain mean with a 31-px reader.
  const Config q = load_config(test::source_path("configs/quick.json"), {"model.fusion_cost_radius_px=3"});
  CHECK(model::net_options(q).fusion.cost_radius_px == 3);
  CHECK(model::net_options(q).fusion.depth_radius_px == 4);
  CHECK_THROWS_WITH(load_config(test::source_path("configs/quick.json"), {"model.fusion_reader_box_px=8"}),
                    Catch::Contains("fusion_reader_box_px"));
  CHECK_THROWS_WITH(load_config(test::source_path("configs/quick.json"), {"model.fusion_guide_eps=0"}),
                    Catch::Contains("fusion_guide_eps"));
  CHECK_THROWS_WITH(load_config(test::source_path("configs/quick.json"), {"model.fusion_depth_radius_px=-1"}),
                    Catch::Contains("fusion_depth_radius_px"));
  model::NetOptions first = o;
  first.fusion = {31, 0, 0, 0.1};
  model::HsdNet plain(first, torch::rand({4, 3}));
  torch::manual_seed(25);
  plain->set_spectral_prior(torch::rand({4}) * 0.3, 1e-3 * (torch::matmul(a, a.t()) + 0.1 * torch::eye(4)), 1e-5,
                            torch::rand({3, 4}));
  plain->set_band_psf(psf / psf.sum({2, 3}, true));
  plain->eval();
  const model::NetOutput pe = plain->forward(x);
  const torch::Tensor z31 = model::defocus_layer_depth(plain->fusion_reader_cost(x), o.layer_depths_m).unsqueeze(1);
  CHECK((pe.depth_m - 0.5 * (head_depth(pe) + z31)).abs().max().item<double>() < 1e-6);
  // The same PSFs at every layer (the all-in-focus control): the reader has no cue, its costs tie everywhere, and
  // it reads the layers' mean depth, not the nearest layer.
  plain->set_band_psf((psf / psf.sum({2, 3}, true)).narrow(1, 0, 1).expand({4, 2, 9, 9}).contiguous());
  CHECK((plain->reader_depth(x, model::fusion_guide(pe.hs)) - 1.25).abs().max().item<double>() < 1e-6);
}

TEST_CASE("spectral defocus likelihood: differentiable in the image (central differences, float64), the PSFs and prior constants",
          "[defocus][gradient]") {
  torch::manual_seed(25);
  const int64_t L = 4, K = 3, P = 5, H = 10, W = 9;
  const torch::Tensor psf = random_psfs(L, K, P).requires_grad_(true), omega = torch::rand({3, L}, torch::kFloat64);
  const model::SpectralPrior prior = random_prior(L);
  const torch::Tensor img = (0.2 + torch::rand({1, 3, H, W}, torch::kFloat64)).requires_grad_(true);
  // A scalar of every layer's cost with uneven weights, so a layer's sign matters.
  const torch::Tensor wts = torch::randn({1, K, H, W}, torch::kFloat64);
  auto objective = [&](const torch::Tensor& x) { return (model::spectral_defocus_cost_volume(x, psf, omega, prior, 5) * wts).sum(); };
  const torch::Tensor f = objective(img);
  REQUIRE(f.requires_grad());
  const torch::Tensor g = torch::autograd::grad({f}, {img}, {}, /*retain_graph=*/false, /*create_graph=*/false,
                                                /*allow_unused=*/false)[0];
  CHECK(g.abs().max().item<double>() > 0);
  CHECK(!psf.grad().defined());  // the PSFs enter as constants
  torch::NoGradGuard ng;
  const double h = 1e-6;
  const std::vector<std::array<int64_t, 3>> pixels = {{0, 0, 0}, {1, 4, 3}, {2, 9, 8}, {0, 5, 7}, {2, 2, 1}};
  for (const auto& [c, i, j] : pixels) {
    torch::Tensor up = img.detach().clone(), dn = img.detach().clone();
    up[0][c][i][j] += h;
    dn[0][c][i][j] -= h;
    const double fd = (objective(up) - objective(dn)).item<double>() / (2 * h);
    const double ad = g[0][c][i][j].item<double>();
    INFO("pixel " << c << "," << i << "," << j << ": autograd " << ad << ", central difference " << fd);
    CHECK(std::abs(ad - fd) <= 1e-6 * std::max(1.0, std::abs(fd)));
  }
}

TEST_CASE("defocus likelihood: model.defocus_cost_gradient lets the loss reach the image through the spectral cost volume, and "
          "changes nothing forward",
          "[defocus][gradient]") {
  torch::manual_seed(26);
  model::NetOptions o;
  o.bands = 4, o.base_width = 8, o.levels = 2, o.norm = NormKind::group, o.residual_spectral_wiener = true;
  o.defocus_cost = DefocusCost::spectral, o.layer_depths_m = {0.5, 2.0}, o.depth_min_m = 0.4, o.depth_max_m = 2.5;
  const torch::Tensor weights = torch::rand({4, 3}), a = torch::rand({4, 4}), mean = torch::rand({4}) * 0.3,
                      omega = torch::rand({3, 4}), psf0 = torch::rand({4, 2, 9, 9});
  const torch::Tensor cov = 1e-3 * (torch::matmul(a, a.t()) + 0.1 * torch::eye(4)), psf = psf0 / psf0.sum({2, 3}, true);
  const torch::Tensor x = torch::rand({2, 3, 24, 20});
  // The depth output's gradient with respect to the image, with the option off and on (same weights).
  auto run = [&](bool graded) {
    model::NetOptions p = o;
    p.defocus_cost_gradient = graded;
    torch::manual_seed(27);
    model::HsdNet net(p, weights);
    net->set_spectral_prior(mean, cov, 1e-5, omega);
    net->set_band_psf(psf);
    net->train();
    const torch::Tensor xi = x.clone().requires_grad_(true);
    const model::NetOutput out = net->forward(xi);
    const torch::Tensor g = torch::autograd::grad({out.inv_depth.sum()}, {xi})[0];
    return std::make_pair(out.inv_depth.detach(), g);
  };
  const auto [off_depth, off_grad] = run(false);
  const auto [on_depth, on_grad] = run(true);
  CHECK(torch::equal(off_depth, on_depth));  // the forward pass is the same
  // The cost volume's path adds to the image's gradient.
  const double diff = (on_grad - off_grad).abs().max().item<double>();
  INFO("largest change of the image's gradient: " << diff << " (off: " << off_grad.abs().max().item<double>() << ")");
  CHECK(diff > 1e-4 * off_grad.abs().max().item<double>());
  CHECK(torch::isfinite(on_grad).all().item<bool>());
  // Refused without the spectral cost volume, naming the key.
  CHECK_THROWS_WITH(
      load_config(test::source_path("configs/quick.json"), {"model.defocus_cost=\"none\"", "model.defocus_cost_gradient=true"}),
      Catch::Contains("defocus_cost_gradient"));
  CHECK(model::net_options(load_config(test::source_path("configs/quick.json"),
                                       {"model.defocus_cost=\"spectral\"", "model.defocus_cost_gradient=true"}))
            .defocus_cost_gradient);
}
