// How well a PSF stack tells depths apart, band by band: the total-variation
// distance between two normalised PSFs, TV(P, Q) = ½ Σ |P − Q| ∈ [0, 1]
// (0: identical, 1: disjoint), and for each band λ the smallest distance over
// every pair of depth layers,
//   d_λ = min_{z ≠ z'} TV(P_λ,z, P_λ,z').
// A band with d_λ ≈ 0 carries no depth cue for that pair: e.g. a lens focused
// at the harmonic middle of the layers gives mirror-image defocus for near and
// far layers at equal inverse-depth distance (the same PSF for an even pupil).
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

}  // namespace hsd::optics
