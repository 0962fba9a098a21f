#include "data/patch_sampler.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::data {

namespace {
// Sums of x [H, W] over every S×S window: [H−S+1, W−S+1] (float64 integral image).
torch::Tensor window_sums(const torch::Tensor& x, int64_t S) {
  torch::Tensor I = torch::zeros({x.size(0) + 1, x.size(1) + 1}, torch::kFloat64);
  I.narrow(0, 1, x.size(0)).narrow(1, 1, x.size(1)).copy_(x.to(torch::kFloat64).cumsum(0).cumsum(1));
  const int64_t h = x.size(0) - S + 1, w = x.size(1) - S + 1;
  return I.narrow(0, S, h).narrow(1, S, w) - I.narrow(0, 0, h).narrow(1, S, w) - I.narrow(0, S, h).narrow(1, 0, w) +
         I.narrow(0, 0, h).narrow(1, 0, w);
}
std::vector<int64_t> positions(int64_t n, int64_t stride) {  // 0, stride, ..., and the last one
  std::vector<int64_t> p;
  for (int64_t v = 0; v < n; v += stride) p.push_back(v);
  if (p.back() != n - 1) p.push_back(n - 1);
  return p;
}
}  // namespace

PatchSampler::PatchSampler(const std::vector<LoadedScene>& scenes, int64_t patch_px, int64_t depth_bins,
                           int64_t stride_px, int64_t overhang_px)
    : scenes_(scenes), patch_(patch_px), overhang_(overhang_px) {
  if (depth_bins < 1 || stride_px < 1) throw InputError("patch sampler: depth_bins and stride must be >= 1");
  if (overhang_px < 0) throw InputError("patch sampler: the overhang must be >= 0");
  if (overhang_px > 0)  // the scenes continued by their replicated edges; candidates in these coordinates
    for (auto& s : scenes_) {
      namespace F = torch::nn::functional;
      const int64_t o = overhang_px;
      auto pad = [&](const torch::Tensor& t) {
        return F::pad(t.unsqueeze(0), F::PadFuncOptions({o, o, o, o}).mode(torch::kReplicate)).squeeze(0);
      };
      s.scene.spectral = pad(s.scene.spectral), s.scene.depth_m = pad(s.scene.depth_m), s.scene.mask = pad(s.scene.mask);
    }
  struct Scored {
    Candidate c;
    double inv_depth;
  };
  std::vector<Scored> all;
  const double full = double(patch_px) * double(patch_px);
  for (size_t s = 0; s < scenes_.size(); ++s) {
    const auto& sc = scenes_[s].scene;
    const int64_t H = sc.spectral.size(1), W = sc.spectral.size(2);
    if (H < patch_px || W < patch_px) continue;
    const torch::Tensor valid = (sc.mask[0] > 0.5).to(torch::kFloat64);
    const torch::Tensor inv = torch::where(valid > 0, 1.0 / sc.depth_m[0].to(torch::kFloat64).clamp_min(1e-9), torch::zeros_like(valid));
    const torch::Tensor count = window_sums(valid, patch_px), inv_sum = window_sums(inv, patch_px);
    const auto cnt = count.accessor<double, 2>();
    const auto isum = inv_sum.accessor<double, 2>();
    for (int64_t y : positions(count.size(0), stride_px))
      for (int64_t x : positions(count.size(1), stride_px))
        if (cnt[y][x] > full - 0.5) all.push_back({{int64_t(s), y, x}, isum[y][x] / full});
  }
  if (all.empty())
    throw InputError("no scene has a fully valid " + std::to_string(patch_px) + "x" + std::to_string(patch_px) +
                     " window (lower data.patch_size_px or check the masks)");
  double lo = all[0].inv_depth, hi = all[0].inv_depth;
  for (const auto& a : all) lo = std::min(lo, a.inv_depth), hi = std::max(hi, a.inv_depth);
  bins_.assign(size_t(depth_bins), {});
  for (const auto& a : all) {
    const int64_t b = hi > lo ? std::min<int64_t>(depth_bins - 1, int64_t((a.inv_depth - lo) / (hi - lo) * double(depth_bins))) : 0;
    bins_[size_t(b)].push_back(a.c);
  }
  bins_.erase(std::remove_if(bins_.begin(), bins_.end(), [](const auto& b) { return b.empty(); }), bins_.end());
  total_ = int64_t(all.size());
}

int64_t PatchSampler::depth_bins_used() const { return int64_t(bins_.size()); }

std::vector<PatchSpec> PatchSampler::draw(int64_t count, uint64_t seed, int64_t illuminants, double intensity_min,
                                          double intensity_max) const {
  std::mt19937_64 rng(seed);
  std::vector<PatchSpec> out;
  out.reserve(size_t(std::max<int64_t>(0, count)));
  for (int64_t i = 0; i < count; ++i) {
    const auto& bin = bins_[std::uniform_int_distribution<size_t>(0, bins_.size() - 1)(rng)];
    const Candidate& c = bin[std::uniform_int_distribution<size_t>(0, bin.size() - 1)(rng)];
    PatchSpec p;
    p.scene = c.scene, p.y = c.y - overhang_, p.x = c.x - overhang_;
    p.flip = std::uniform_int_distribution<int>(0, 1)(rng) == 1;
    p.rot90 = std::uniform_int_distribution<int64_t>(0, 3)(rng);
    if (illuminants > 0) p.lighting = draw_lighting(rng, illuminants, intensity_min, intensity_max);
    out.push_back(p);
  }
  return out;
}

Patch PatchSampler::extract(const PatchSpec& spec, const IlluminantBank* bank) const {
  if (spec.scene < 0 || spec.scene >= int64_t(scenes_.size())) throw InputError("patch spec names no scene");
  const auto& sc = scenes_[size_t(spec.scene)].scene;
  auto crop = [&](const torch::Tensor& t) {
    torch::Tensor c = t.narrow(1, spec.y + overhang_, patch_).narrow(2, spec.x + overhang_, patch_);
    if (spec.flip) c = c.flip({2});
    if (spec.rot90) c = torch::rot90(c, spec.rot90, {1, 2});
    return c.contiguous();
  };
  Patch p;
  p.spec = spec;
  p.spectral = crop(sc.spectral);
  if (sc.kind == SpectralKind::Reflectance) {
    if (bank == nullptr) throw InputError("a reflectance scene needs an illuminant bank to make radiance");
    p.spectral = light_reflectance(p.spectral, bank->spectrum(spec.lighting.illuminant), spec.lighting.scale);
  } else {
    p.spectral = p.spectral * spec.lighting.scale;
  }
  p.depth_m = crop(sc.depth_m);
  p.mask = crop(sc.mask);
  return p;
}

}  // namespace hsd::data
