// Evaluation metrics on known inputs: identical images, a constant offset,
// a hand-computed SSIM case, symmetry and bounds, luminance weights, depth
// errors ignoring masked pixels, and the ColorChecker patch RMSE.
#include <catch2/catch.hpp>
#include <cmath>

#include "common/error.h"
#include "train/metrics.h"

using namespace hsd;

TEST_CASE("metrics: PSNR and SSIM on known inputs", "[metrics]") {
  torch::manual_seed(1);
  const torch::Tensor a = torch::rand({3, 32, 40}, torch::kFloat64);
  CHECK(train::psnr_db(a, a, 1.0) == train::kPsnrCapDb);  // identical: capped
  CHECK(train::ssim(a, a, 1.0) == Approx(1.0).epsilon(1e-12));
  // A constant offset c: MSE = c², PSNR = 10 log10(R²/c²) = 20 log10(R/c).
  CHECK(train::psnr_db(a + 0.1, a, 1.0) == Approx(20.0).epsilon(1e-9));
  CHECK(train::psnr_db(a + 0.1, a, 2.0) == Approx(20.0 + 20.0 * std::log10(2.0)).epsilon(1e-9));
  // Two constant images x, y: variances and covariance vanish, so
  // SSIM = (2xy + C1)/(x² + y² + C1) · (C2/C2), C1 = (0.01 R)².
  const double x = 0.3, y = 0.5, C1 = 1e-4;
  CHECK(train::ssim(torch::full({1, 20, 20}, x, torch::kFloat64), torch::full({1, 20, 20}, y, torch::kFloat64), 1.0) ==
        Approx((2 * x * y + C1) / (x * x + y * y + C1)).epsilon(1e-9));
  // Symmetric and bounded.
  const torch::Tensor b = (a + 0.2 * torch::randn({3, 32, 40}, torch::kFloat64)).clamp(0, 1);
  CHECK(train::psnr_db(a, b, 1.0) == Approx(train::psnr_db(b, a, 1.0)));
  CHECK(train::ssim(a, b, 1.0) == Approx(train::ssim(b, a, 1.0)));
  const double s = train::ssim(a, b, 1.0);
  CHECK(s < 1.0);
  CHECK(s > -1.0);
  CHECK(train::ssim(a, 1.0 - a, 1.0) < 0.0);  // anti-correlated structure
}

TEST_CASE("metrics: luminance, depth errors with a mask, ColorChecker RMSE", "[metrics]") {
  const torch::Tensor cube = torch::stack({torch::full({2, 2}, 1.0), torch::full({2, 2}, 3.0)});  // [2, 2, 2]
  CHECK(train::luminance(cube, torch::tensor({1.0, 3.0}))[0][0][0].item<double>() == Approx(2.5));  // (1·1 + 3·3)/4
  torch::Tensor truth = torch::ones({1, 4, 4}), pred = torch::ones({1, 4, 4}), mask = torch::ones({1, 4, 4});
  pred[0][0][0] = 100.0;  // a wild value in a masked pixel must not count
  mask[0][0][0] = 0.0;
  pred[0][3][3] = 1.5;
  const auto e = train::depth_errors(pred, truth, mask);
  CHECK(e.mae_m == Approx(0.5 / 15));
  CHECK(e.rmse_m == Approx(std::sqrt(0.25 / 15)));
  // Patch reflectance: radiance = reflectance × E, recovered by dividing.
  const torch::Tensor E = torch::tensor({0.5, 1.0}, torch::kFloat64);
  torch::Tensor rad = torch::zeros({2, 4, 8}, torch::kFloat64);
  rad.narrow(2, 0, 4).select(0, 0).fill_(0.2 * 0.5), rad.narrow(2, 0, 4).select(0, 1).fill_(0.4);
  rad.narrow(2, 4, 4).select(0, 0).fill_(0.9 * 0.5), rad.narrow(2, 4, 4).select(0, 1).fill_(0.1);
  const torch::Tensor rec = train::patch_reflectances(rad, E, {{0, 0, 4, 4}, {4, 0, 8, 4}});
  CHECK((rec - torch::tensor({0.2, 0.4, 0.9, 0.1}, torch::kFloat64).view({2, 2})).abs().max().item<double>() < 1e-12);
  const torch::Tensor tru = torch::tensor({0.2, 0.5, 0.9, 0.1}, torch::kFloat64).view({2, 2});
  CHECK(train::mean_patch_rmse(rec, tru) == Approx((std::sqrt(0.01 / 2) + 0.0) / 2));
}

TEST_CASE("metrics: the interior mask drops the pixels within the margin of every border, by hand", "[metrics]") {
  torch::Tensor mask = torch::ones({1, 5, 6});
  mask[0][2][3] = 0.0;  // an invalid pixel inside stays invalid
  const torch::Tensor in = train::interior_mask(mask, 1);
  CHECK(in.sizes() == mask.sizes());
  // Rows 1..3, columns 1..4 survive (3 x 4 = 12), less the invalid one.
  CHECK(in.sum().item<double>() == 11.0);
  CHECK(in.narrow(1, 0, 1).sum().item<double>() == 0.0);
  CHECK(in.narrow(1, 4, 1).sum().item<double>() == 0.0);
  CHECK(in.narrow(2, 0, 1).sum().item<double>() == 0.0);
  CHECK(in.narrow(2, 5, 1).sum().item<double>() == 0.0);
  CHECK(in[0][2][3].item<double>() == 0.0);
  CHECK(in[0][1][1].item<double>() == 1.0);
  CHECK(train::interior_mask(mask, 0).equal(mask));            // no margin: the valid mask itself
  CHECK(train::interior_mask(mask, 3).sum().item<double>() == 0.0);  // 2 x 3 > 5 rows: nothing is interior
  CHECK(train::interior_mask(mask, 100).sum().item<double>() == 0.0);
  CHECK(mask.sum().item<double>() == 29.0);  // the input is untouched
  CHECK_THROWS_AS(train::interior_mask(mask, -1), InputError);
  CHECK_THROWS_AS(train::interior_mask(torch::ones({5, 6}), 1), InputError);
}
