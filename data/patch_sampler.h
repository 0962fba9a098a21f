// Training patches (the paper: 20,000 patches of 256×256 from valid regions):
// every patch lies entirely inside a scene's valid mask, or, with an overhang
// o > 0, inside the scene continued past its border by o px of its replicated
// edge (the whole-scene renderer's padding, optics/sensor_image.h), so that
// windows rendered with o px of margin put their centre anywhere in the scene,
// the border band included; positions are drawn so
// that patches cover the depth range evenly (candidates binned by their mean
// inverse depth, bins drawn uniformly), then flipped and rotated by multiples
// of 90°, and (reflectance scenes) lit by a random illuminant at a random
// global intensity. Deterministic for a seed.
#pragma once
#include <cstdint>
#include <vector>

#include <torch/types.h>

#include "data/dataset.h"
#include "data/illuminant_augment.h"

namespace hsd::data {

struct PatchSpec {
  int64_t scene = 0, y = 0, x = 0;  // top-left corner in the scene (>= -overhang)
  bool flip = false;                // mirror left-right, before the rotation
  int64_t rot90 = 0;                // counter-clockwise quarter turns
  Lighting lighting;
};

struct Patch {
  torch::Tensor spectral;  // float32 [L, S, S]: radiance (reflectance scenes lit per spec.lighting)
  torch::Tensor depth_m;   // float32 [1, S, S]
  torch::Tensor mask;      // float32 [1, S, S] (all valid)
  PatchSpec spec;
};

class PatchSampler {
 public:
  // InputError when no scene has a fully valid patch_px × patch_px window.
  // overhang_px >= 0: how far a window may reach past each side of a scene.
  PatchSampler(const std::vector<LoadedScene>& scenes, int64_t patch_px, int64_t depth_bins = 8, int64_t stride_px = 4,
               int64_t overhang_px = 0);

  // `count` specs drawn with the seed; illuminant indices in [0, illuminants).
  std::vector<PatchSpec> draw(int64_t count, uint64_t seed, int64_t illuminants, double intensity_min,
                              double intensity_max) const;
  // The patch of a spec; `bank` lights reflectance scenes (required for them).
  Patch extract(const PatchSpec& spec, const IlluminantBank* bank) const;

  int64_t candidates() const { return total_; }
  int64_t depth_bins_used() const;

 private:
  struct Candidate {
    int64_t scene, y, x;
  };
  std::vector<LoadedScene> scenes_;  // a copy: tensors are shared, not duplicated (padded by overhang_ when > 0)
  int64_t patch_, overhang_;
  std::vector<std::vector<Candidate>> bins_;
  int64_t total_ = 0;
};

}  // namespace hsd::data
