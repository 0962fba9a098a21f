// The pictures written at each validation (out/<run>/val/step_NNNNNN_*.png):
// a montage with a row per patch [truth | sensor | reconstruction | |error| |
// true depth | predicted depth], enlarged 3×, and the PSF atlas of the
// current DOE (every band × depth layer).
#pragma once
#include <string>
#include <vector>

#include <torch/torch.h>

#include "model/unet.h"

namespace hsd::train {

struct ValidationPictures {
  torch::Tensor truth;                // radiance I [n, L, S, S]
  torch::Tensor depth_m;              // true depth Z [n, 1, S, S] m
  torch::Tensor sensor;               // sensor image J [n, 3, S, S]
  model::NetOutput out;               // the network's reconstruction of J (hs [n, L, S, S], depth_m [n, 1, S, S])
  std::vector<double> wavelengths_m;  // the bands' centres [L]
  double band_width_m = 0;
  double near_m = 0, far_m = 0;       // the depth pictures' colour range
  torch::Tensor psf;                  // [L, Z, P, P] the imaging PSFs
  std::vector<double> depths_m;       // the PSFs' depth layers [Z]
};

// Writes <stem>reconstructions.png and <stem>psf_atlas.png (the montage's
// pieces are written, assembled and removed).
void write_validation_pictures(const std::string& stem, const ValidationPictures& v);

}  // namespace hsd::train
