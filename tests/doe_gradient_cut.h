// Test helper: a switch that cuts one path of the DOE's gradient
// (train.spectral_wiener_doe_gradient, train.preinverse_doe_gradient) must
// leave the forward pass as it is and remove only that path's share.
#pragma once
#include <catch2/catch.hpp>

#include "train/trainer.h"

namespace hsd::test {

// a (the full gradient) and b (the path cut) start alike and take one step on
// the same batch: the same loss, a non-zero DOE gradient in b, and b's differing
// from a's by more than 1e-3 of its size.
inline void check_doe_gradient_cut(train::Trainer& a, train::Trainer& b, const train::Batch& batch) {
  const double la = a.step(batch, 0).loss, lb = b.step(batch, 0).loss;
  CHECK(la == Approx(lb).epsilon(1e-6));
  const torch::Tensor ga = a.doe().parameter().grad(), gb = b.doe().parameter().grad();
  REQUIRE(ga.defined());
  REQUIRE(gb.defined());
  CHECK(gb.abs().max().item<double>() > 0.0);  // the DOE still learns, through the sensor image
  const double diff = (ga - gb).abs().max().item<double>();
  INFO("gradient through the cut path: " << diff << " of " << ga.abs().max().item<double>());
  CHECK(diff > 1e-3 * ga.abs().max().item<double>());  // and that path's share is gone
}

}  // namespace hsd::test
