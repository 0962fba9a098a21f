// The model library's own pieces: the network a config builds (net_options)
// and the typed normalisation choice. The network's numerics are tested where
// they are used: test_export (TorchScript = C++), test_precision (bfloat16),
// test_preinverse (Wiener input), test_baselines (heads at the baselines).
#include <catch2/catch.hpp>

#include "common/config.h"
#include "common/error.h"
#include "helpers.h"
#include "model/net_options.h"
#include "model/spectral_upsampling.h"
#include "model/unet.h"

using namespace hsd;

TEST_CASE("net_options: the depth head spans the layers and the scenes, widened by model.depth_margin in inverse depth", "[model]") {
  Config cfg = load_config(test::source_path("configs/base.json"), {"model.depth_margin=0"});
  const double near = std::min(cfg.optics.depths_m.front(), cfg.data.generator.depth_min_m);
  const double far = std::max(cfg.optics.depths_m.back(), cfg.data.generator.depth_max_m);
  model::NetOptions o = model::net_options(cfg);
  CHECK(o.bands == int64_t(cfg.optics.wavelengths_nm.size()));
  CHECK(o.depth_min_m == Approx(near));
  CHECK(o.depth_max_m == Approx(far));
  CHECK(o.preinverse_layers == 0);
  CHECK(o.norm == cfg.model.norm);
  // A margin m widens [1/far, 1/near] by m·span at each end (scenes to 2 m,
  // so the far end stays clear of its floor at half its inverse depth).
  cfg = load_config(test::source_path("configs/base.json"), {"model.depth_margin=0.1", "data.generator.depth_max_m=2.0", "model.preinverse=wiener",
                                                             "model.residual=preinverse", "model.norm=group"});
  o = model::net_options(cfg);
  const double far2 = 2.0, span = 1.0 / near - 1.0 / far2;
  CHECK(1.0 / o.depth_min_m == Approx(1.0 / near + 0.1 * span));
  CHECK(1.0 / o.depth_max_m == Approx(1.0 / far2 - 0.1 * span));
  CHECK(o.preinverse_layers == int64_t(cfg.optics.depths_m.size()));
  CHECK(o.residual_preinverse);
  CHECK(o.norm == NormKind::group);
  // A margin that would pass infinity keeps the far end at half its inverse depth.
  cfg = load_config(test::source_path("configs/base.json"), {"model.depth_margin=0.5"});
  CHECK(model::net_options(cfg).depth_max_m == Approx(2.0 * far));
}

TEST_CASE("model.norm is parsed once into its type, and any other word is refused naming the key", "[model][config]") {
  for (const NormKind k : {NormKind::batch, NormKind::group, NormKind::none})
    CHECK(load_config(test::source_path("configs/base.json"), {"model.norm=" + choice_name(k)}).model.norm == k);
  try {
    load_config(test::source_path("configs/base.json"), {"model.norm=layer"});
    FAIL("model.norm=layer was accepted");
  } catch (const InputError& e) {
    CHECK(std::string(e.what()).find("model.norm") != std::string::npos);
    CHECK(std::string(e.what()).find("\"batch\", \"group\" or \"none\"") != std::string::npos);
  }
}

TEST_CASE("model.spectral_map: learned makes the residual's map a parameter started at the paper's, whose gradient is the upsampling's, and fixed keeps it a buffer", "[model]") {
  Config cfg = load_config(test::source_path("configs/base.json"), {"model.base_width=4", "model.levels=1"});
  CHECK((cfg.model.spectral_map == SpectralMap::fixed));
  model::NetOptions o = model::net_options(cfg);
  CHECK_FALSE(o.learned_spectral_map);
  const int64_t L = o.bands;
  const torch::Tensor omega = torch::rand({3, L}, torch::TensorOptions().dtype(torch::kFloat64)) + 0.1;
  const torch::Tensor w = model::spectral_upsampling_weights(omega).to(torch::kFloat32);
  auto has = [](const auto& dict, const std::string& key) { return dict.find(key) != nullptr; };
  {
    model::HsdNet fixed(o, w);
    CHECK(has(fixed->named_buffers(), "upsampling_weights"));
    CHECK_FALSE(has(fixed->named_parameters(), "upsampling_weights"));
  }
  cfg = load_config(test::source_path("configs/base.json"), {"model.base_width=4", "model.levels=1", "model.spectral_map=learned"});
  o = model::net_options(cfg);
  REQUIRE(o.learned_spectral_map);
  model::HsdNet net(o, w);
  CHECK_FALSE(has(net->named_buffers(), "upsampling_weights"));
  REQUIRE(has(net->named_parameters(), "upsampling_weights"));
  CHECK(torch::equal(net->upsampling_weights(), w));
  // With the cube head at zero the cube is W·image, so for the loss Σ G ⊙ cube
  // the map's gradient is Σ_pixels G ⊗ image (and the head's weight gets one too).
  net->start_at_baselines(1.0);
  net->eval();
  torch::manual_seed(3);
  const torch::Tensor image = torch::rand({2, 3, 8, 6}), G = torch::randn({2, L, 8, 6});
  (net->forward(image).hs * G).sum().backward();
  const torch::Tensor expected = torch::einsum("blhw,bchw->lc", {G, image});
  REQUIRE(net->upsampling_weights().grad().defined());
  CHECK(torch::allclose(net->upsampling_weights().grad(), expected, 1e-4, 1e-4));
  try {
    load_config(test::source_path("configs/base.json"), {"model.spectral_map=fitted"});
    FAIL("model.spectral_map=fitted was accepted");
  } catch (const InputError& e) {
    CHECK(std::string(e.what()).find("model.spectral_map") != std::string::npos);
  }
}

TEST_CASE("model.base_as_input: the residual's base is input beside the image, the cube then depends on it beyond the sum, and the heads still start at it", "[model]") {
  Config cfg = load_config(test::source_path("configs/base.json"), {"model.base_width=4", "model.levels=1", "model.norm=group"});
  CHECK_FALSE(cfg.model.base_as_input);
  model::NetOptions off = model::net_options(cfg);
  CHECK_FALSE(off.base_as_input);
  cfg = load_config(test::source_path("configs/base.json"),
                    {"model.base_width=4", "model.levels=1", "model.norm=group", "model.base_as_input=true"});
  model::NetOptions on = model::net_options(cfg);
  REQUIRE(on.base_as_input);
  // An explicit base (the spectral Wiener residual takes it as an argument),
  // so that the base alone can change while the image stays.
  off.residual_spectral_wiener = on.residual_spectral_wiener = true;
  const int64_t L = on.bands;
  torch::manual_seed(5);
  const torch::Tensor w = torch::rand({L, 3});
  model::HsdNet without(off, w), with(on, w);
  auto first_block = [](model::HsdNet& n) {
    for (const auto& p : n->named_parameters())
      if (p.key().rfind("down0.", 0) == 0 && p.value().dim() == 4) return p.value();
    return torch::Tensor();
  };
  REQUIRE(first_block(without).defined());
  REQUIRE(first_block(with).defined());
  CHECK(first_block(without).size(1) == 3);
  CHECK(first_block(with).size(1) == 3 + L);  // the image and the L bands of its base
  without->eval(), with->eval();
  const torch::Tensor image = torch::rand({2, 3, 8, 8}), base = torch::rand({2, L, 8, 8}),
                      delta = 0.2 * torch::randn({2, L, 8, 8});
  {
    torch::NoGradGuard ng;
    // Random heads. Without the option the base only adds: the cube moves by
    // exactly δ. With it the network reads the base: δ plus its response.
    auto response = [&](model::HsdNet& n) {
      return (n->forward(image, {}, base + delta).hs - n->forward(image, {}, base).hs - delta).abs().max().item<double>();
    };
    CHECK(response(without) < 1e-6);
    CHECK(response(with) > 1e-3);
    // The depth head too reads it.
    CHECK((with->forward(image, {}, base + delta).depth_m - with->forward(image, {}, base).depth_m).abs().max().item<double>() > 1e-5);
    CHECK(torch::equal(without->forward(image, {}, base + delta).depth_m, without->forward(image, {}, base).depth_m));
    // Started at the baselines (cube head zero) the cube is the base exactly.
    with->start_at_baselines(1.0);
    CHECK(torch::equal(with->forward(image, {}, base).hs, base));
  }
  // The paper's residual on the image: the base is the image's spectral
  // upsampling, and the first block gets its gradient on those channels.
  on.residual_spectral_wiener = false;
  model::HsdNet up(on, w);
  up->train();
  up->forward(image).depth_m.sum().backward();
  const torch::Tensor g = first_block(up).grad();
  REQUIRE(g.defined());
  CHECK(g.narrow(1, 3, L).abs().sum().item<double>() > 0.0);
  up->start_at_baselines(1.0);
  torch::NoGradGuard ng;
  CHECK(torch::allclose(up->forward(image).hs, model::spectral_upsample(w, image), 0.0, 1e-6));
}

TEST_CASE("model.depth_bins: the bins head reads the softmax's expectation over k/(N-1), starts at the constant, and bad counts are refused naming the key", "[model][depth]") {
  Config cfg = load_config(test::source_path("configs/base.json"),
                           {"model.base_width=4", "model.levels=1", "model.norm=group", "model.depth_bins=8"});
  model::NetOptions o = model::net_options(cfg);
  REQUIRE(o.depth_bins == 8);
  torch::manual_seed(11);
  model::HsdNet net(o, torch::rand({o.bands, 3}));
  net->eval();
  torch::NoGradGuard ng;
  const torch::Tensor image = torch::rand({2, 3, 8, 10});
  // Random weights: the logits come out, and the depth is their softmax's
  // expectation mapped onto the head's range in inverse depth.
  const model::NetOutput r = net->forward(image);
  REQUIRE(r.depth_logits.defined());
  REQUIRE(r.depth_logits.sizes() == c10::IntArrayRef{2, 8, 8, 10});
  const torch::Tensor t = torch::linspace(0.0, 1.0, 8).view({1, -1, 1, 1});
  const torch::Tensor u = (torch::softmax(r.depth_logits, 1) * t).sum(1, true);
  const double inv_far = 1.0 / o.depth_max_m, inv_near = 1.0 / o.depth_min_m;
  CHECK((r.depth_unit - u).abs().max().item<double>() < 1e-6);
  CHECK((r.inv_depth - (inv_far + u * (inv_near - inv_far))).abs().max().item<double>() < 1e-5);
  CHECK(r.depth_unit.std().item<double>() > 1e-4);  // not constant: the logits vary over the pixels
  // At the baselines every pixel's depth is the constant, wherever it falls between two bins.
  for (double z : {0.55, 0.8, 1.3, 2.2}) {
    net->start_at_baselines(1.0 / z);
    const model::NetOutput s = net->forward(image);
    INFO("constant " << z << " m");
    CHECK((s.depth_m - z).abs().max().item<double>() < 1e-5 * z);
  }
  // The sigmoid head has no logits.
  model::NetOptions sig = o;
  sig.depth_bins = 0;
  model::HsdNet plain(sig, torch::rand({o.bands, 3}));
  plain->eval();
  CHECK_FALSE(plain->forward(image).depth_logits.defined());
  for (const std::vector<std::string>& bad : std::vector<std::vector<std::string>>{
           {"model.depth_bins=1"}, {"model.depth_bins=-2"}, {"train.depth_ce_weight=0.5"}}) {
    try {
      load_config(test::source_path("configs/base.json"), bad);
      FAIL(bad[0] << " was accepted");
    } catch (const InputError& e) {
      const std::string key = bad[0].substr(0, bad[0].find('='));
      INFO(e.what());
      CHECK(std::string(e.what()).find(key) != std::string::npos);
    }
  }
}
