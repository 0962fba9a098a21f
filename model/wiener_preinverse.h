// Wiener pre-inversion of the sensor image for every depth layer (Ikoma et
// al., ICCP 2021, "Depth from defocus with learned optics", its "preinverse"
// input): for layer k and colour channel c,
//   X_k,c = F⁻¹[ conj(H_k,c) · F(J_c) / (|H_k,c|² + ρ) ],
// H_k,c the OTF of the camera's RGB PSF of that layer,
//   P_k,c = Σ_λ Ω_c,λ P_λ,k / Σ_λ Ω_c,λ      (a grey scene's PSF in channel c),
// ρ the regulariser (noise-to-signal power; the PSFs sum to 1, so |H(0)| = 1).
// The layer whose PSF made a region deconvolves it sharply and the others
// ring, so the network can read depth (and a deblurred image for the cube)
// locally, where a U-Net would otherwise need a receptive field wider than the
// PSF. Differentiable in the image and the PSFs (so the DOE learns through it).
// Borders: the image is extended by edge replication to an FFT-friendly size
// at least H + P − 1 (as the sensor model extends the scene), so the circular
// deconvolution does not wrap across the image.
#pragma once
#include <torch/types.h>

namespace hsd::model {

// psf [L, K, P, P] (per band and layer, each summing to 1), omega [3, L] camera
// response -> [K, 3, P, P], each channel's PSF summing to 1 (channels with no
// response: zeros).
torch::Tensor camera_rgb_psfs(const torch::Tensor& psf, const torch::Tensor& omega);

// image [B, C, H, W], rgb_psf [K, C, P, P] (P odd), reg ρ > 0 ->
// [B, K·C, H, W], channel k·C + c = layer k's deconvolution of channel c.
// Float32 (float64 inputs stay float64, for gradient checks).
torch::Tensor wiener_preinverse(const torch::Tensor& image, const torch::Tensor& rgb_psf, double reg);

// PSFs [.., P, P] (P odd) zero-padded to [.., nh, nw] and rolled so their
// centre sits at pixel (0, 0): the layout whose DFT is the OTF of a
// convolution that does not shift the image. Shared by the readers of
// defocus_likelihood.h.
torch::Tensor centred_padded_psf(const torch::Tensor& psf, int64_t nh, int64_t nw);

// The mean over the K layers of a pre-inversion [B, K·C, H, W] -> [B, C, H, W]:
// one deconvolved image without choosing a layer. Upsampled spectrally, it is
// the network's residual base with model.residual = "preinverse" and the
// evaluation's Wiener baseline (train/baselines.h).
torch::Tensor preinverse_layer_mean(const torch::Tensor& preinverse, int64_t layers);

}  // namespace hsd::model
