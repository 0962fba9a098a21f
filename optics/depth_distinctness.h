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
// is not a point. Model it as a stationary Gaussian texture with a natural
// image's power spectrum S(f) ∝ 1/(|f|² + f₀²) (normalised to mean 1 over
// the frequencies, i.e. unit variance), blurred by the PSF and read with
// white noise of variance σ² (relative to the texture's). The image is then
// Gaussian with power spectrum P_z(f) = S(f)|H_z(f)|² + σ² (H: the PSF's DFT,
// f in cycles per pixel), so **only the MTF |H| carries depth**: a PSF change
// that is a shift, or mostly a change of phase (a pattern rotating at fine
// scale), is invisible in a scene however large its total variation. The
// scene cue between two depths is the symmetric Kullback-Leibler divergence
// of the two image models per pixel (nats; independent frequencies),
//   D(z, z') = mean_f ½ (P_z − P_z')² / (P_z P_z'),
// so a patch of n pixels carries about n·D nats to tell z from z'.
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

// The scene model's pieces, shared with scene_fisher.h: the DFT size for
// P-px PSFs (at least 2P and 128), |H|² of PSFs [..., P, P] zero-padded to
// it [..., N, N], and the texture spectrum S [N, N] (mean 1).
int64_t scene_dft_size(int64_t psf_px);
torch::Tensor psf_mtf2(const torch::Tensor& psf, int64_t n);
torch::Tensor natural_texture_spectrum(int64_t n, double corner_cycles_per_px, c10::ScalarType dtype);

struct SceneDepthCue {
  std::vector<double> min_per_slice;              // [L] smallest D over depth pairs
  std::vector<double> mean_per_slice;             // [L] mean D over depth pairs
  std::vector<std::pair<int64_t, int64_t>> pair;  // [L] the (z, z') of the smallest
};

// psf [L, Z, P, P] (bands or camera channels; each slice sums to 1); Z >= 2.
// noise_variance: σ² relative to the texture's variance (> 0);
// corner_cycles_per_px: f₀ (> 0). Float64, on DFTs zero-padded to at least 2P
// and 128 samples.
SceneDepthCue scene_depth_cue(const torch::Tensor& psf, double noise_variance, double corner_cycles_per_px = 1.0 / 64);

}  // namespace hsd::optics
