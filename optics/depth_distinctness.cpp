#include "optics/depth_distinctness.h"

#include <limits>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {

DepthDistinctness depth_distinctness(const torch::Tensor& psf) {
  if (psf.dim() != 4 || psf.size(1) < 2) throw InputError("depth distinctness: needs a PSF stack [L, Z >= 2, P, P]");
  const torch::Tensor p = psf.detach().to(torch::kFloat64).cpu();
  DepthDistinctness d;
  for (int64_t l = 0; l < p.size(0); ++l) {
    double best = std::numeric_limits<double>::infinity();
    std::pair<int64_t, int64_t> at{0, 1};
    for (int64_t a = 0; a < p.size(1); ++a)
      for (int64_t b = a + 1; b < p.size(1); ++b) {
        const double tv = 0.5 * (p[l][a] - p[l][b]).abs().sum().item<double>();
        if (tv < best) best = tv, at = {a, b};
      }
    d.per_band.push_back(best);
    d.pair.push_back(at);
  }
  return d;
}

}  // namespace hsd::optics
