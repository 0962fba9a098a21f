// The Wiener pre-inversion (model/wiener_preinverse.h): closed forms (a delta
// PSF, the camera's RGB PSF of a known response), recovery of a blurred scene
// with the right layer's PSF and not with a wrong one, a float64 gradient check
// in the image and the PSFs, and the network's input with it switched on.
#include <catch2/catch.hpp>

#include <torch/torch.h>

#include <cmath>
#include <filesystem>

#include "common/error.h"
#include "doe_gradient_cut.h"
#include "helpers.h"
#include "model/spectral_upsampling.h"
#include "model/unet.h"
#include "model/wiener_preinverse.h"
#include "train/baselines.h"
#include "train/trainer.h"

using namespace hsd;
namespace F = torch::nn::functional;

namespace {

// Normalised Gaussian PSFs [K, C, P, P] of widths sigma_px (one per layer).
torch::Tensor gaussian_psfs(const std::vector<double>& sigma_px, int64_t C, int64_t P, c10::ScalarType dtype) {
  const torch::Tensor t = torch::arange(P, dtype) - double(P / 2);
  std::vector<torch::Tensor> layers;
  for (double s : sigma_px) {
    torch::Tensor g = torch::exp(-(t.view({-1, 1}).square() + t.view({1, -1}).square()) / (2 * s * s));
    layers.push_back((g / g.sum()).expand({C, P, P}));
  }
  return torch::stack(layers);
}

// The sensor model's convolution: the scene extended by edge replication, then a linear convolution.
torch::Tensor blur(const torch::Tensor& x, const torch::Tensor& psf_cpp) {
  const int64_t C = x.size(1), r = psf_cpp.size(-1) / 2;
  const torch::Tensor xp = F::pad(x, F::PadFuncOptions({r, r, r, r}).mode(torch::kReplicate));
  // conv2d correlates: flip the kernel to convolve.
  return F::conv2d(xp, psf_cpp.flip({-2, -1}).unsqueeze(1), F::Conv2dFuncOptions().groups(C));
}

Config tiny_wiener(const std::string& residual = "image") {
  return load_config(test::source_path("configs/tiny.json"),
                     {"data.root=\"unused_no_data_is_loaded\"", "model.base_width=4", "model.levels=2",
                      "train.batch_size=2", "train.warmup_steps=0", "train.decay=none", "data.patch_size_px=16",
                      "train.lr_net=0.003", "model.preinverse=\"wiener\"", "model.residual=\"" + residual + "\""});
}

train::Batch tiny_batch(int64_t L) {
  torch::manual_seed(5);
  train::Batch b;
  b.radiance = torch::rand({2, L, 16, 16});
  b.depth_m = 0.5 + torch::rand({2, 1, 16, 16});
  return b;
}

double rel(const torch::Tensor& a, const torch::Tensor& b) {
  return ((a - b).norm() / b.norm().clamp_min(1e-30)).item<double>();
}

}  // namespace

TEST_CASE("preinverse: a delta PSF returns the image over 1 + rho in every layer", "[preinverse]") {
  torch::manual_seed(1);
  const torch::Tensor x = torch::rand({2, 3, 13, 17}, torch::kFloat64);
  torch::Tensor delta = torch::zeros({2, 3, 5, 5}, torch::kFloat64);
  delta.select(2, 2).select(2, 2).fill_(1.0);
  const double rho = 0.25;
  const torch::Tensor y = model::wiener_preinverse(x, delta, rho);
  REQUIRE(y.sizes() == c10::IntArrayRef{2, 6, 13, 17});
  CHECK((y.narrow(1, 0, 3) - x / (1 + rho)).abs().max().item<double>() < 1e-12);
  CHECK((y.narrow(1, 3, 3) - x / (1 + rho)).abs().max().item<double>() < 1e-12);
}

TEST_CASE("preinverse: the residual base is the layers' mean deconvolution, upsampled, with delta PSFs the image over 1 + rho",
          "[preinverse][baselines]") {
  torch::manual_seed(6);
  const torch::Tensor x = torch::rand({2, 3, 12, 10});
  const torch::Tensor w = torch::rand({4, 3});
  torch::Tensor delta = torch::zeros({3, 3, 5, 5});
  delta.select(2, 2).select(2, 2).fill_(1.0);
  const double rho = 0.25;
  const torch::Tensor base = train::wiener_upsampling_cube(x, delta, rho, w);
  REQUIRE(base.sizes() == c10::IntArrayRef{2, 4, 12, 10});
  CHECK((base - model::spectral_upsample(w, x) / (1 + rho)).abs().max().item<double>() < 1e-5);
  // Layer mean by hand: [B, K*C, H, W] with layer k filled with k + c/10.
  torch::Tensor p = torch::empty({1, 6, 2, 2});
  for (int k = 0; k < 2; ++k)
    for (int c = 0; c < 3; ++c) p[0][3 * k + c].fill_(k + c / 10.0);
  const torch::Tensor m = model::preinverse_layer_mean(p, 2);
  REQUIRE(m.sizes() == c10::IntArrayRef{1, 3, 2, 2});
  for (int c = 0; c < 3; ++c) CHECK(m[0][c][1][1].item<double>() == Approx(0.5 + c / 10.0));
  CHECK_THROWS(model::preinverse_layer_mean(p, 4));  // 6 channels are not 4 layers of C
  // A network with the residual on the deconvolutions and its heads at the
  // baselines answers with exactly this baseline; without the pre-inversion it refuses.
  model::NetOptions o;
  o.bands = 4, o.base_width = 4, o.levels = 2, o.norm = NormKind::group, o.preinverse_layers = 2, o.preinverse_reg = 0.01;
  o.residual_preinverse = true;
  model::HsdNet net(o, w);
  const torch::Tensor psf = gaussian_psfs({1.0, 2.5}, 3, 9, torch::kFloat32);
  net->set_preinverse_psf(psf);
  net->start_at_baselines(1.0);
  torch::NoGradGuard ng;
  const torch::Tensor y = torch::rand({2, 3, 20, 24});
  const torch::Tensor expect = train::wiener_upsampling_cube(y, psf, 0.01, w);
  CHECK((net->forward(y).hs - expect).abs().max().item<double>() < 1e-6);
  CHECK((expect - model::spectral_upsample(w, y)).abs().max().item<double>() > 1e-3);  // not the image's upsampling
  o.preinverse_layers = 0;
  CHECK_THROWS(model::HsdNet(o, w));
}

TEST_CASE("preinverse: the camera's RGB PSF is the response-weighted band mean", "[preinverse]") {
  // 2 bands, 1 layer, P = 3: band 0 a delta, band 1 uniform; channel 0 sees
  // band 0 only, channel 1 both equally (weights 2 and 2), channel 2 nothing.
  torch::Tensor psf = torch::zeros({2, 1, 3, 3}, torch::kFloat64);
  psf[0][0][1][1] = 1.0;
  psf[1][0].fill_(1.0 / 9);
  const torch::Tensor omega = torch::tensor({1.0, 0.0, 2.0, 2.0, 0.0, 0.0}, torch::kFloat64).view({3, 2});
  const torch::Tensor rgb = model::camera_rgb_psfs(psf, omega);
  REQUIRE(rgb.sizes() == c10::IntArrayRef{1, 3, 3, 3});
  CHECK((rgb[0][0] - psf[0][0]).abs().max().item<double>() < 1e-15);
  CHECK((rgb[0][1] - 0.5 * (psf[0][0] + psf[1][0])).abs().max().item<double>() < 1e-15);
  CHECK(rgb[0][2].abs().max().item<double>() == 0.0);  // no response: zeros, not NaN
  CHECK(rgb[0][1].sum().item<double>() == Approx(1.0).epsilon(1e-14));
}

TEST_CASE("preinverse: the right layer's PSF recovers a blurred scene, a wrong one does not", "[preinverse]") {
  torch::manual_seed(2);
  // A smooth random scene (12 x 12 noise upsampled bicubically to 48 x 48), 3 channels.
  const torch::Tensor scene = F::interpolate(torch::rand({1, 3, 12, 12}, torch::kFloat64),
                                             F::InterpolateFuncOptions()
                                                 .size(std::vector<int64_t>{48, 48})
                                                 .mode(torch::kBicubic)
                                                 .align_corners(false));
  const torch::Tensor psfs = gaussian_psfs({0.7, 2.0}, 3, 15, torch::kFloat64);  // layer 0 sharp, layer 1 wide
  const torch::Tensor image = blur(scene, psfs[1]);                               // the scene at layer 1
  const torch::Tensor y = model::wiener_preinverse(image, psfs, 1e-4);
  // Away from the borders, where the replicated extension of the image is not
  // the blurred replicated scene.
  auto rms = [](const torch::Tensor& a, const torch::Tensor& b) {
    return (a - b).narrow(2, 12, 24).narrow(3, 12, 24).square().mean().sqrt().item<double>();
  };
  const double blurred = rms(image, scene), right = rms(y.narrow(1, 3, 3), scene), wrong = rms(y.narrow(1, 0, 3), scene);
  INFO("rms error: blurred image " << blurred << ", right layer " << right << ", wrong layer " << wrong);
  CHECK(right < 0.2 * blurred);
  CHECK(wrong > 0.5 * blurred);
  CHECK(wrong > 4 * right);
}

TEST_CASE("preinverse: gradients in the image and the PSFs match central differences (float64)", "[preinverse]") {
  torch::manual_seed(3);
  const torch::Tensor x = torch::rand({1, 2, 9, 11}, torch::kFloat64);
  const torch::Tensor p = torch::rand({2, 2, 5, 5}, torch::kFloat64) + 0.1;
  const torch::Tensor w = torch::randn({1, 4, 9, 11}, torch::kFloat64);  // a fixed random functional
  auto f = [&](const torch::Tensor& xx, const torch::Tensor& pp) {
    return (model::wiener_preinverse(xx, pp, 0.05) * w).sum();
  };
  for (const auto& g : test::image_psf_gradient_check(f, x, p, 1e-6)) {
    INFO(g.input << " entry " << g.entry);
    CHECK(g.autograd == Approx(g.difference).epsilon(1e-6).margin(1e-9));
  }
}

TEST_CASE("preinverse: the network takes the deconvolutions beside the image", "[preinverse]") {
  torch::manual_seed(4);
  model::NetOptions o;
  o.bands = 5, o.base_width = 8, o.levels = 2, o.norm = NormKind::group, o.preinverse_layers = 2, o.preinverse_reg = 0.01;
  model::HsdNet net(o, torch::rand({5, 3}));
  net->eval();
  const torch::Tensor x = torch::rand({1, 3, 20, 20});
  CHECK_THROWS_WITH(net->forward(x), Catch::Contains("set_preinverse_psf"));
  CHECK_THROWS(net->set_preinverse_psf(torch::rand({3, 3, 5, 5})));  // 3 layers for a 2-layer network
  net->set_preinverse_psf(gaussian_psfs({1.0, 2.0}, 3, 7, torch::kFloat32));
  torch::NoGradGuard ng;
  const model::NetOutput a = net->forward(x), b = net->forward(x, net->preinverse(x));
  CHECK(torch::equal(a.hs, b.hs));
  CHECK(torch::equal(a.depth_m, b.depth_m));
  // The input matters: a different pre-inversion changes the output.
  const model::NetOutput c = net->forward(x, torch::zeros({1, 6, 20, 20}));
  CHECK((c.hs - a.hs).abs().max().item<double>() > 0);
}

TEST_CASE("preinverse: training with it lowers the loss, reaches the DOE, profiles exactly and resumes", "[train][preinverse]") {
  const Config cfg = tiny_wiener(GENERATE(std::string("image"), std::string("preinverse")));
  INFO("model.residual " << choice_name(cfg.model.residual));
  train::Trainer a(cfg), b(cfg);
  const int64_t L = int64_t(a.psf().spec().wavelengths_m.size()), Z = int64_t(a.psf().spec().depths_m.size());
  REQUIRE(a.net()->options().preinverse_layers == Z);
  const auto bt = tiny_batch(L);
  train::StepProfile prof;
  b.set_profile(&prof);
  const double first = a.step(bt, 0).loss;
  b.step(bt, 0);
  REQUIRE(a.doe().parameter().grad().defined());
  CHECK(a.doe().parameter().grad().abs().max().item<double>() > 0.0);
  double last = first;
  for (int k = 1; k < 8; ++k) last = a.step(bt, k).loss, b.step(bt, k);
  CHECK(last < first);
  CHECK(rel(b.height(), a.height()) < 1e-6);  // the profiled step's three-part backward is the same chain rule
  const auto pa = a.net()->named_parameters(), pb = b.net()->named_parameters();
  for (const auto& p : pa) {
    INFO(p.key());
    CHECK(rel(pb[p.key()], p.value()) < 1e-6);
  }
  // After a step the network holds detached PSFs: it runs forward and backward alone.
  CHECK_FALSE(a.net()->preinverse_psf().requires_grad());
  const auto o = a.net()->forward(torch::rand({1, 3, 16, 16}));
  CHECK_NOTHROW((o.hs.mean() + o.depth_m.mean()).backward());
  // A checkpoint restores the network's PSFs from the loaded DOE.
  const std::string ck = (std::filesystem::temp_directory_path() / "hsd_test_preinverse_ck.pt").string();
  a.save_checkpoint(ck, 8);
  train::Trainer c(cfg);
  c.load_checkpoint(ck);
  a.refresh_preinverse();
  const torch::Tensor expect = model::camera_rgb_psfs(a.psf_stack(), a.sensor().omega);
  CHECK(rel(c.net()->preinverse_psf(), expect) < 1e-6);
  CHECK(rel(a.net()->preinverse_psf(), expect) < 1e-6);
}

TEST_CASE("preinverse: under train.fabrication_noise the camera images through the perturbed DOE but deconvolves with the design's PSFs",
          "[train][preinverse][fabrication]") {
  Config cfg = tiny_wiener();
  train::Trainer clean(cfg);
  cfg.train.fabrication_noise.height_scale_error = 0.3;
  cfg.train.fabrication_noise.edge_blur_m = 8e-6;
  train::Trainer noisy(cfg);
  const int64_t L = int64_t(noisy.psf().spec().wavelengths_m.size());
  const auto bt = tiny_batch(L);
  REQUIRE(rel(noisy.height(), clean.height()) == 0.0);
  noisy.refresh_preinverse();
  const torch::Tensor design = model::camera_rgb_psfs(noisy.psf_stack(), noisy.sensor().omega);
  const double loss_clean = clean.step(bt, 0).loss, loss_noisy = noisy.step(bt, 0).loss;
  // The step's pre-inversion held the design's PSFs (the DOE before the
  // step), while the image came through other PSFs: the losses differ.
  CHECK(rel(noisy.net()->preinverse_psf(), design) < 1e-6);
  CHECK(rel(clean.net()->preinverse_psf(), design) < 1e-6);
  CHECK(std::fabs(loss_noisy - loss_clean) > 1e-6 * std::fabs(loss_clean));
}

TEST_CASE("preinverse: with train.fabrication_noise_calibrated the step deconvolves with the perturbed PSFs, and without noise it changes nothing",
          "[train][preinverse][fabrication]") {
  Config cfg = tiny_wiener();
  train::Trainer clean(cfg);
  cfg.train.fabrication_noise_calibrated = true;
  train::Trainer calibrated_clean(cfg);  // no noise: the perturbed surface is the design
  cfg.train.fabrication_noise.height_scale_error = 0.3;
  cfg.train.fabrication_noise.edge_blur_m = 8e-6;
  train::Trainer calibrated(cfg);
  cfg.train.fabrication_noise_calibrated = false;
  train::Trainer uncalibrated(cfg);
  const int64_t L = int64_t(clean.psf().spec().wavelengths_m.size());
  const auto bt = tiny_batch(L);
  clean.refresh_preinverse();
  const torch::Tensor design = model::camera_rgb_psfs(clean.psf_stack(), clean.sensor().omega);
  const double l_clean = clean.step(bt, 0).loss, l_cal_clean = calibrated_clean.step(bt, 0).loss;
  const double l_cal = calibrated.step(bt, 0).loss, l_uncal = uncalibrated.step(bt, 0).loss;
  CHECK(l_cal_clean == l_clean);
  // The same draw images both noisy steps; the uncalibrated one deconvolves
  // with the design's PSFs, the calibrated one with the drawn surface's.
  CHECK(rel(uncalibrated.net()->preinverse_psf(), design) < 1e-6);
  CHECK(rel(calibrated.net()->preinverse_psf(), design) > 1e-3);
  CHECK(std::fabs(l_cal - l_uncal) > 1e-6 * std::fabs(l_uncal));
}

TEST_CASE("preinverse: a profiled step under train.fabrication_noise gives the DOE the same gradient as an unprofiled one",
          "[train][preinverse][fabrication]") {
  // Profiling cuts the graph at each PSF stack (the perturbed surface's and the
  // design's) and runs the backward in parts; the chain rule must come out whole.
  Config cfg = tiny_wiener();
  cfg.train.fabrication_noise.height_scale_error = 0.3;
  cfg.train.fabrication_noise.edge_blur_m = 8e-6;
  train::Trainer plain(cfg), profiled(cfg);
  train::StepProfile prof;
  profiled.set_profile(&prof);
  const auto bt = tiny_batch(int64_t(plain.psf().spec().wavelengths_m.size()));
  const double la = plain.step(bt, 0).loss, lb = profiled.step(bt, 0).loss;
  CHECK(la == Approx(lb).epsilon(1e-6));
  const torch::Tensor ga = plain.doe().parameter().grad(), gb = profiled.doe().parameter().grad();
  REQUIRE(ga.defined());
  REQUIRE(gb.defined());
  CHECK(ga.abs().sum().item<double>() > 0.0);
  CHECK(rel(gb, ga) < 1e-4);
  CHECK(prof.psf_forward > 0.0);
  CHECK(prof.psf_backward > 0.0);
}

TEST_CASE("preinverse: train.preinverse_doe_gradient = false leaves the forward as it is and cuts only the filters' gradient into the DOE",
          "[train][preinverse]") {
  Config with = tiny_wiener(), without = tiny_wiener();
  without.train.preinverse_doe_gradient = false;
  train::Trainer a(with), b(without);
  const int64_t L = int64_t(a.psf().spec().wavelengths_m.size());
  const auto bt = tiny_batch(L);
  test::check_doe_gradient_cut(a, b, bt);  // the same seed: the same network and DOE
}
