// The first two moments of the radiance spectra a training run sees: over the
// valid pixels of the scenes, reflectance lit by each illuminant of the bank
// (equally likely) times a global intensity s ~ U[lo, hi], radiance scenes
// times s (data/illuminant_augment.h, the patch sampler's lighting):
//   μ = E[s] · E_k[e_k ⊙ m_r],  E[x xᵀ] = E[s²] · E_k[diag(e_k) R_r diag(e_k)],
// m_r and R_r the pixels' mean and second moment, each pixel weighted
// equally. The prior of the spectral Wiener cube (model/spectral_wiener.h).
#pragma once
#include <vector>

#include <torch/types.h>

#include "data/dataset.h"

namespace hsd::data {

struct SpectralMoments {
  torch::Tensor mean;        // [L] float64
  torch::Tensor covariance;  // [L, L] float64, E[x xᵀ] − μ μᵀ
  int64_t pixels = 0;        // valid pixels counted
};

// scenes on L bands; illuminants [N, L] (band means; needed when a scene is a
// reflectance); intensity range 0 < lo <= hi. InputError when no scene has a
// valid pixel or a reflectance scene meets an empty bank.
SpectralMoments radiance_moments(const std::vector<LoadedScene>& scenes, const torch::Tensor& illuminants,
                                 double intensity_min, double intensity_max);

// The reflectance's own moments over the valid pixels of reflectance scenes
// (each pixel weighted equally): m_r [L] and R_r = E[r rᵀ] [L, L], float64,
// the unlit factors of the moments above (model/illuminant_reader.h lights
// them one illuminant at a time). InputError naming the file when a scene is
// a radiance (its light cannot be taken out), or when no pixel is valid.
struct ReflectanceMoments {
  torch::Tensor mean;    // [L]
  torch::Tensor second;  // [L, L]
  int64_t pixels = 0;
};
ReflectanceMoments reflectance_moments(const std::vector<LoadedScene>& scenes);

}  // namespace hsd::data
