// The cube's second stage (model/cube_refiner.h, model.refine_width): the
// network adds R([y, x₁]) to its first stage's cube x₁, starts at the
// baselines with it on, passes gradients to both stages and the image, keeps
// any input size, and the config and the export handle it with clear errors.
#include <catch2/catch.hpp>

#include <torch/torch.h>

#include "common/config.h"
#include "common/error.h"
#include "helpers.h"
#include "model/cube_refiner.h"
#include "model/net_options.h"
#include "model/torchscript_export.h"
#include "model/unet.h"

using namespace hsd;

namespace {

// A network with the spectral Wiener residual taking an explicit base, so the
// first stage's cube is known without optics.
model::NetOptions small_options(int64_t refine_width) {
  model::NetOptions o;
  o.bands = 5, o.base_width = 4, o.levels = 2, o.norm = NormKind::group, o.residual_spectral_wiener = true;
  o.refine_width = refine_width;
  return o;
}

}  // namespace

TEST_CASE("cube refiner: the cube is the first stage's plus R([image, first stage]), exactly R of a refiner with the same weights",
          "[model][refiner]") {
  torch::manual_seed(3);
  const model::NetOptions o = small_options(4);
  model::HsdNet net(o, torch::rand({o.bands, 3}));
  // Only the refiner's parameters are new, under "refiner.".
  int64_t refiner_params = 0;
  for (const auto& p : net->named_parameters()) refiner_params += p.key().rfind("refiner.", 0) == 0;
  CHECK(refiner_params > 0);
  model::HsdNet one_stage(small_options(0), torch::rand({o.bands, 3}));
  CHECK(int64_t(net->named_parameters().size()) == int64_t(one_stage->named_parameters().size()) + refiner_params);
  // A standalone refiner with the network's refiner weights.
  model::CubeRefinerOptions ro;
  ro.in_channels = 3, ro.bands = o.bands, ro.base_width = 4, ro.levels = 2, ro.norm = NormKind::group;
  model::CubeRefiner alone(ro);
  {
    torch::NoGradGuard ng;
    auto mine = net->named_parameters();
    for (auto& p : alone->named_parameters()) p.value().copy_(mine["refiner." + p.key()]);
  }
  net->eval(), alone->eval();
  // Odd sizes: padded inside, cropped back.
  const torch::Tensor image = torch::rand({2, 3, 10, 14}), base = torch::rand({2, o.bands, 10, 14});
  torch::NoGradGuard ng;
  // Started at the baselines both heads are zero: the cube is the base exactly.
  net->start_at_baselines(1.0);
  CHECK(torch::equal(net->forward(image, {}, base).hs, base));
  // A random refiner head, the first stage still zero: x₂ = base + R([y, base]).
  for (auto& p : net->named_parameters())
    if (p.key().rfind("refiner.head", 0) == 0) p.value().normal_(0.0, 0.3);
  for (auto& p : alone->named_parameters())
    if (p.key().rfind("head", 0) == 0) p.value().copy_(net->named_parameters()["refiner." + p.key()]);
  const torch::Tensor r = alone->forward(image, base);
  REQUIRE(r.sizes() == base.sizes());
  REQUIRE(r.abs().max().item<double>() > 1e-3);
  const model::NetOutput two = net->forward(image, {}, base);
  const torch::Tensor& hs = two.hs;
  CHECK((hs - (base + r)).abs().max().item<double>() < 1e-6);
  // The first stage's cube is reported beside the final one (train.first_stage_cube_weight).
  REQUIRE(two.first_stage_hs.defined());
  CHECK(torch::equal(two.first_stage_hs, base));
  // The refiner reads the cube, not only the image.
  CHECK((alone->forward(image, base + 0.2) - r).abs().max().item<double>() > 1e-4);
  // Depth is the first stage's alone: a refiner changes nothing there.
  model::HsdNet same(small_options(0), torch::rand({o.bands, 3}));
  {
    auto mine = net->named_parameters();
    for (auto& p : same->named_parameters()) p.value().copy_(mine[p.key()]);
  }
  same->eval();
  CHECK(torch::equal(same->forward(image, {}, base).depth_m, net->forward(image, {}, base).depth_m));
  CHECK_FALSE(same->forward(image, {}, base).first_stage_hs.defined());
}

TEST_CASE("cube refiner: the loss's gradient reaches both stages and the image", "[model][refiner]") {
  torch::manual_seed(4);
  const model::NetOptions o = small_options(4);
  model::HsdNet net(o, torch::rand({o.bands, 3}));
  net->train();
  const torch::Tensor image = torch::rand({2, 3, 8, 8}).requires_grad_(true), base = torch::rand({2, o.bands, 8, 8});
  net->forward(image, {}, base).hs.pow(2).mean().backward();
  double first = 0.0, second = 0.0;
  for (const auto& p : net->named_parameters()) {
    if (!p.value().grad().defined()) continue;
    const double g = p.value().grad().abs().sum().item<double>();
    (p.key().rfind("refiner.", 0) == 0 ? second : first) += g;
  }
  CHECK(first > 0.0);
  CHECK(second > 0.0);
  REQUIRE(image.grad().defined());
  CHECK(image.grad().abs().sum().item<double>() > 0.0);
  // A term on the first stage's cube alone (deep supervision) reaches the
  // first stage and not the refiner: first_stage_hs is x₁, before R.
  net->zero_grad();
  net->forward(image, {}, base).first_stage_hs.pow(2).mean().backward();
  first = 0.0, second = 0.0;
  for (const auto& p : net->named_parameters()) {
    if (!p.value().grad().defined()) continue;
    const double g = p.value().grad().abs().sum().item<double>();
    (p.key().rfind("refiner.", 0) == 0 ? second : first) += g;
  }
  CHECK(first > 0.0);
  CHECK(second == 0.0);
}

TEST_CASE("cube refiner: model.refine_width and train.first_stage_cube_weight from the config, refused naming the key, and no export", "[model][refiner]") {
  Config cfg = load_config(test::source_path("configs/tiny.json"), {});
  CHECK(cfg.model.refine_width == 0);
  CHECK(model::net_options(cfg).refine_width == 0);
  cfg = load_config(test::source_path("configs/tiny.json"), {"model.refine_width=8"});
  CHECK(model::net_options(cfg).refine_width == 8);
  CHECK_THROWS_WITH(load_config(test::source_path("configs/tiny.json"), {"model.refine_width=-1"}),
                    Catch::Contains("model.refine_width"));
  // Deep supervision of the first stage needs a second stage, and is >= 0.
  CHECK(load_config(test::source_path("configs/tiny.json"), {"model.refine_width=8", "train.first_stage_cube_weight=0.5"})
            .train.first_stage_cube_weight == 0.5);
  CHECK_THROWS_WITH(load_config(test::source_path("configs/tiny.json"), {"train.first_stage_cube_weight=0.5"}),
                    Catch::Contains("train.first_stage_cube_weight"));
  CHECK_THROWS_WITH(load_config(test::source_path("configs/tiny.json"), {"model.refine_width=8", "train.first_stage_cube_weight=-1"}),
                    Catch::Contains("first_stage_cube_weight"));
  model::HsdNet net(small_options(4), torch::rand({5, 3}));
  const model::ExportMetadata meta{{450e-9, 500e-9, 550e-9, 600e-9, 650e-9}, {{"camera", "test"}}, {}};
  CHECK_THROWS_WITH(model::export_torchscript(net, meta), Catch::Contains("refine_width"));
}
