// HS-D sensor image formation (the paper's "Sensor Image Synthesis"):
//   J_c = Σ_z M_z ⊙ Σ_λ Ω_c,λ (I_λ ⊗ P_λ,z),   c ∈ {R, G, B}
// Depth layers are the configured depths (optics.depths_m, linear in inverse
// depth); a pixel belongs to the layer nearest to its depth in inverse depth;
// M_z is that binary occupancy filtered with a Gaussian of σ pixels (Chang &
// Wetzstein 2019; Wu et al. 2019).
//
// Fast path: by linearity, per layer the bands are summed in the Fourier domain,
// Σ_λ Ω_c,λ FFT(I_λ) OTF_λ,z, so each layer costs 3 inverse real FFTs instead of
// L; each band's image FFT is computed once. Convolution is linear, not
// circular: the scene is extended by the PSF radius with edge replication, so
// nothing wraps around and borders do not darken. Layers no pixel occupies and
// bands whose response is zero are left out, with identical results.
#pragma once
#include <vector>

#include <torch/types.h>

#include "common/fft_size.h"  // the convolutions' FFT size

namespace hsd::optics {

// Index of the nearest layer in inverse depth: depth_m [B, 1, H, W] (metres,
// finite and > 0, else InputError naming the problem) -> int64 [B, 1, H, W].
torch::Tensor nearest_layer(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m);

// Soft layer masks M_z: one-hot occupancy [B, Z, H, W] filtered with a Gaussian
// of sigma_px (0 = binary), edge-replicated at the borders.
torch::Tensor layer_masks(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m, double sigma_px);

// Layers that some pixel occupies (binary occupancy, any image of the batch).
std::vector<int64_t> occupied_layers(const torch::Tensor& depth_m, const std::vector<double>& layer_depths_m);

// J [B, 3, H, W] from radiance [B, L, H, W], masks [B, Z', H, W], psf [L, Z', P, P]
// (the PSFs of the same Z' layers as the masks, in the same order) and camera
// response omega [3, L]. Bands the camera does not see (a zero column of
// omega) and layers no pixel occupies (a zero mask) are left out.
torch::Tensor render_sensor_image(const torch::Tensor& radiance, const torch::Tensor& masks, const torch::Tensor& psf,
                                  const torch::Tensor& omega);

// Occlusion-aware layered compositing (Ikoma et al., ICCP 2021, "Depth from
// defocus with learned optics"), layers ordered far to near by
// layer_depths_m (the depths of the alphas' layers, in their order):
//   E_k = (Σ_{j far-or-equal k} α_j) ⊗ P_k,  b_k = ((α_k I) ⊗ P_k) / E_k,  a_k = (α_k ⊗ P_k) / E_k
//   y_λ = Σ_k b_k Π_{k' nearer than k} (1 − a_k'),   J_c = Σ_λ Ω_c,λ y_λ
// (blurred-alpha normalisation, then "over" compositing). Each (λ, z) needs its
// own convolutions, so this costs about 3× the straightforward linear model.
// alphas [B, Z', H, W] (binary or soft occupancy), other shapes as above.
torch::Tensor render_sensor_image_occlusion(const torch::Tensor& radiance, const torch::Tensor& alphas,
                                            const torch::Tensor& psf, const torch::Tensor& omega,
                                            const std::vector<double>& layer_depths_m);

// The straightforward evaluation of the same equation, one FFT convolution per
// (λ, z); the reference the fast path is tested and benchmarked against.
torch::Tensor render_sensor_image_direct(const torch::Tensor& radiance, const torch::Tensor& masks,
                                         const torch::Tensor& psf, const torch::Tensor& omega);

}  // namespace hsd::optics
