// The trivial answers every learned result is reported against, on the same
// pixels (docs/evaluation.md, "Baselines"):
//   constant depth: one depth for every pixel, 1 / m̃ with m̃ the median of the
//     training split's valid inverse depths [1/m]: the constant that minimises
//     the training loss's L1 term on inverse depth over the training pixels.
//   upsampling: the spectral-upsampling cube of the sensor image
//     (model/spectral_upsampling.h), the network's residual input without the
//     network: what the U-Net adds is the difference from it.
//   Wiener: the spectral upsampling of the mean over the depth layers of the
//     sensor image's Wiener deconvolutions (model/wiener_preinverse.h) with
//     the imaging DOE's RGB PSFs: a sharper cube with no learning, and the
//     network's residual input when model.residual = "preinverse".
//   spectral Wiener: the LMMSE cube of the sensor image (model/spectral_wiener.h)
//     under the training radiance's spectral moments, with the imaging DOE's
//     band PSFs: the best linear answer, and the network's residual base when
//     model.residual = "spectral_wiener".
// Beside them, a reference that uses the truth (not a baseline a model could
// be, but a ruler for depth): the resolution oracle (data/depth_structure.h);
// the w at which its RMSE equals a model's is that model's effective depth
// resolution. And the layer oracle (layer_oracle_depth_map): the image is
// rendered with one PSF per configured depth layer (optics/sensor_image.h), so
// the optical cue says at most which layer a pixel is in; a reader that knows
// each pixel's layer exactly, and the mean depth of the scene's pixels in that
// layer, scores the layer oracle. What a network reads beyond it comes from
// the scene's content, not from the optics.
#pragma once
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "data/dataset.h"
#include "model/illuminant_reader.h"
#include "model/spectral_wiener.h"
#include "optics/sensor.h"

namespace hsd::train {

// Median of 1/depth over the valid pixels (mask > 0.5) of the scenes [1/m];
// InputError when no scene has a valid pixel.
double median_inverse_depth(const std::vector<data::LoadedScene>& scenes);

// The image the Wiener baseline upsamples: the mean over the K layers of the
// image's Wiener deconvolutions. image [B, C, H, W], rgb_psf [K, C, P, P]
// (model::camera_rgb_psfs of the imaging PSFs), reg ρ > 0 -> [B, C, H, W].
torch::Tensor wiener_mean_image(const torch::Tensor& image, const torch::Tensor& rgb_psf, double reg);

// The Wiener baseline's cube: wiener_mean_image upsampled with
// upsampling_weights [L, C] -> [B, L, H, W].
torch::Tensor wiener_upsampling_cube(const torch::Tensor& image, const torch::Tensor& rgb_psf, double reg,
                                     const torch::Tensor& upsampling_weights);

// The spectral Wiener baseline's prior: the moments of the training split's
// radiance as the trainer lights it (data.illuminants, data.intensity_min/max;
// data/spectral_moments.h) and the sensor model's mean noise variance at the
// mean image level (model::mean_noise_variance).
model::SpectralPrior training_spectral_prior(const std::vector<data::LoadedScene>& train_scenes, const Config& cfg,
                                             const optics::SensorModel& sensor);

// The illuminant reader's moments (model/illuminant_reader.h): the training
// reflectance's, lit one illuminant of data.illuminants at a time, with the
// training intensity range. InputError when a training scene is a radiance.
model::IlluminantMoments training_illuminant_moments(const std::vector<data::LoadedScene>& train_scenes, const Config& cfg);

// The constant-depth map: depth_m [.., H, W] of `like`'s shape, every value 1 / inv_depth [m].
torch::Tensor constant_depth_map(const torch::Tensor& like, double inv_depth_per_m);

// The layer oracle: depth_m [.., H, W] (metres), mask alike (> 0.5 = valid),
// layer_depths_m the rendering layers -> [.., H, W] where each valid pixel holds
// the mean depth [m] (the RMSE-best constant) of the valid pixels of its map
// (the leading index) in the same nearest layer (optics::nearest_layer);
// invalid pixels keep their depth.
torch::Tensor layer_oracle_depth_map(const torch::Tensor& depth_m, const torch::Tensor& mask,
                                     const std::vector<double>& layer_depths_m);

// The window at which an oracle's RMSE equals `rmse`: windows ascending,
// oracle_rmse their RMSEs; linear in log w between the bracketing pair.
// Below the first: the first window; above the last: +inf (coarser than the
// largest box measured). Requires windows and oracle_rmse of equal, non-zero size.
double effective_resolution_px(const std::vector<int64_t>& windows, const std::vector<double>& oracle_rmse, double rmse);

}  // namespace hsd::train
