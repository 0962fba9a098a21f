// How well a PSF stack tells depths apart, band by band: the total-variation
// distance between two normalised PSFs, TV(P, Q) = ½ Σ |P − Q| ∈ [0, 1]
// (0: identical, 1: disjoint), and for each band λ the smallest distance over
// every pair of depth layers,
//   d_λ = min_{z ≠ z'} TV(P_λ,z, P_λ,z').
// A band with d_λ ≈ 0 carries no depth cue for that pair: e.g. a lens focused
// at the harmonic middle of the layers gives mirror-image defocus for near and
// far layers at equal inverse-depth distance (the same PSF for an even pupil).
//
// The total-variation distance is the cue seen through a point source. A scene
// is not a point: its image is the PSF convolved with a texture whose power
// falls as 1/f² (natural images), so a PSF change that only moves light at
// fine scale (a rotation of a many-lobed pattern) barely changes the image,
// while a change of blur width does. The scene-weighted cue measures that:
// for two depths' PSFs with transfer functions H, H' (DFT of the PSF, f in
// cycles per pixel),
//   r(z, z') = Σ_f S(f) |H − H'|² / Σ_f S(f) (|H|² + |H'|²)/2,
//   S(f) = 1 / (|f|² + f₀²),
// the fraction of a 1/f² texture's image power that changes between the two
// depths (0: the same image, up to 2: opposite). f₀ keeps S finite at f = 0.
#pragma once
#include <vector>

#include <torch/types.h>

namespace hsd::optics {

struct DepthDistinctness {
  std::vector<double> per_band;                   // [L] d_λ
  std::vector<std::pair<int64_t, int64_t>> pair;  // [L] the (z, z') that attain it
};

// psf [L, Z, P, P] (each slice sums to 1); Z >= 2.
DepthDistinctness depth_distinctness(const torch::Tensor& psf);

struct SceneDepthCue {
  std::vector<double> min_per_slice;              // [L] smallest r over depth pairs
  std::vector<double> mean_per_slice;             // [L] mean r over depth pairs
  std::vector<std::pair<int64_t, int64_t>> pair;  // [L] the (z, z') of the smallest
};

// psf [L, Z, P, P] (bands or camera channels; each slice sums to 1); Z >= 2.
// corner_cycles_per_px: f₀ of the texture spectrum (> 0). Computed in float64
// on DFTs zero-padded to at least 2P and 128 samples.
SceneDepthCue scene_depth_cue(const torch::Tensor& psf, double corner_cycles_per_px = 1.0 / 64);

}  // namespace hsd::optics
