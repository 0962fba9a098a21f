// The reconstruction network (Baek et al. 2021, "Network Architecture"): a
// U-Net encoder with two decoders sharing its skip connections, one for the
// hyperspectral cube (L channels, added to the residual spectral upsampling of
// the input, spectral_upsampling.h) and one for depth (a sigmoid output read as
// normalised inverse depth, mapped back to metres over the configured range;
// or, with depth_bins, the soft argmax of logits over bins of it).
// Inputs whose sides are not multiples of 2^levels are reflect-padded and the
// outputs cropped back. Every block is conv 3×3 -> norm -> ReLU, twice; down
// by 2×2 max pooling, up by bilinear ×2 then conv. Built only from ops that
// TorchScript also has, so the exporter can re-express it. Batch norm is
// synchronised over data-parallel replicas once set_replica_group is called
// (sync_batch_norm.h); alone it is torch's BatchNorm2d. With refine_width > 0
// a second stage adds its residual to the cube (cube_refiner.h).
// Mixed precision (NetOptions::train_dtype = bfloat16): in training mode the
// convolutions run in bfloat16 on bfloat16 copies of the float32 weights (the
// copies are differentiable casts, so gradients, Adam and its state stay
// float32) in channels-last layout (oneDNN's fast bfloat16 path), the norms
// compute their statistics in float32, and the heads' outputs are float32
// before the sigmoid, the residual and the loss. Eval mode is float32 always.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "common/choices.h"
#include "model/cube_refiner.h"
#include "model/replica_group.h"
#include "model/depth_fusion.h"
#include "model/illuminant_reader.h"
#include "model/spectral_tv.h"
#include "model/spectral_wiener.h"
#include "model/tensor_snapshot.h"

namespace hsd::model {

// net_options(cfg) (model/net_options.h) fills these from a config; the
// defaults here are for a network built by hand.
// The box [px] of the network's spectral cost-volume input (NetOptions::defocus_cost).
inline constexpr int64_t kDefocusInputWindowPx = 15;
// The box [px] of hsd_eval's spectral reader baseline (the fused reader's
// settings are in depth_fusion.h).
inline constexpr int64_t kDefocusReaderWindowPx = 31;

struct NetOptions {
  int64_t in_channels = 3;
  int64_t bands = 25;              // L
  int64_t base_width = 32;         // channels of the first level; doubled per level
  int64_t levels = 4;              // poolings
  NormKind norm = NormKind::batch;
  double depth_min_m = 0.4, depth_max_m = 2.0;
  torch::ScalarType train_dtype = torch::kFloat32;  // kFloat32 | kBFloat16: the convolutions' dtype in training mode
  // Wiener pre-inversion (wiener_preinverse.h): 0 = off (the paper's network);
  // K > 0 = the image's deconvolutions for K depth layers are input beside it
  // (in_channels·(1 + K) channels into the first block).
  int64_t preinverse_layers = 0;
  double preinverse_reg = 1e-2;    // ρ, the Wiener regulariser
  // The cube head's residual base: false = the spectral upsampling of the
  // image (the paper's); true = the spectral upsampling of the mean over the
  // K layers of the Wiener deconvolutions (needs preinverse_layers > 0).
  bool residual_preinverse = false;
  // true = the cube head adds to the spectral Wiener cube of the image
  // (spectral_wiener.h; exclusive with residual_preinverse): its prior is the
  // buffers set by set_spectral_prior, its PSFs the owner's set_band_psf.
  bool residual_spectral_wiener = false;
  // The residual's spectral-upsampling weights: false = a buffer (the paper's
  // fixed map), true = a parameter started at the given weights (learned).
  bool learned_spectral_map = false;
  // true = the residual's base (the cube the head's output is added to) is
  // also input to the first block, beside the image and the pre-inversion
  // (+L channels): the network sees the answer it corrects. false = the
  // paper's network, which adds its residual to a base it does not see.
  bool base_as_input = false;
  // A classical depth-from-defocus cost volume (defocus_likelihood.h, no
  // gradient into the PSFs), less its mean over the K layers, as K more
  // channels into the first block: grey = defocus_cost_volume with the
  // pre-inversion's RGB PSFs (needs preinverse_layers > 0; its default model);
  // spectral = spectral_defocus_cost_volume with the spectral Wiener base's
  // prior and band PSFs (needs residual_spectral_wiener; a 15-px box).
  DefocusCost defocus_cost = DefocusCost::none;
  // (The spectral cost volume's box: kDefocusInputWindowPx; K = layer_depths_m.size().)
  // true (spectral only): the cost volume is differentiable in the image, so
  // the loss reaches the DOE through it as through the image (never through
  // its PSFs); false: no gradient through it at all.
  bool defocus_cost_gradient = false;
  // true (needs residual_spectral_wiener and layer_depths_m): in eval mode the
  // depth is the head's and the spectral reader's averaged in metres, the
  // reader's costs and the average filtered edge-aware under the cube's
  // brightness (depth_fusion.h); training mode is unchanged.
  bool fuse_defocus_reader = false;
  FusionSettings fusion;  // its settings (model.fusion_*)
  // true (needs residual_spectral_wiener): in eval mode the spectral Wiener
  // base uses, for each image, the prior mixed under the posterior of the
  // training illuminants given that image (illuminant_reader.h; moments from
  // set_illuminant_moments) instead of the equal-weight mixture in the
  // buffers; the spectral readers keep the buffers' prior, and training mode
  // is unchanged.
  bool read_illuminant = false;
  IlluminantReaderSettings illuminant_reader;  // its settings (model.illuminant_*)
  // weight > 0 (needs residual_spectral_wiener): in eval mode the spectral
  // Wiener base is the cube with a total-variation edge prior
  // (spectral_tv.h), under the same prior (the illuminant reader's too);
  // training mode is unchanged.
  EdgePriorSettings edge_prior;
  // true (needs residual_spectral_wiener): the cube head's residual δ is
  // added through (I − W H̄) (spectral_wiener_unobserved): only what the image
  // does not determine is the network's to add. W is the filter of the
  // buffers' prior for the network's view (in eval mode too, where
  // read_illuminant changes the base's prior but not this one).
  bool project_residual = false;
  // > 0: a second stage refines the cube (cube_refiner.h): a U-Net of this
  // base width (levels and norm the network's) reads the image and the first
  // stage's cube and adds its residual to it (through (I − W H̄) as well with
  // project_residual). 0 = one stage, the paper's network.
  int64_t refine_width = 0;
  // The rendering layers [m] (optics.depths_m, set by net_options): K for the
  // cost volume and the reader's depths.
  std::vector<double> layer_depths_m;
  // The depth head: 0 = one sigmoid output read as normalised inverse depth
  // (the paper's); N >= 2 = N logits over bins at t_k = k/(N-1) of the
  // normalised inverse depth, read as their softmax's expectation Σ p_k t_k
  // (a soft argmax; depth_logits carries them for a classification loss).
  int64_t depth_bins = 0;
};

struct NetOutput {
  torch::Tensor hs;          // [B, L, H, W] radiance per band
  // [B, L, H, W] the first stage's cube x₁ with the second stage on (refine_width > 0); undefined otherwise.
  torch::Tensor first_stage_hs;
  torch::Tensor inv_depth;   // [B, 1, H, W] 1/m
  torch::Tensor depth_m;     // [B, 1, H, W] metres
  torch::Tensor depth_unit;  // [B, 1, H, W] the depth head's sigmoid output in [0, 1] (for saturation diagnostics)
  torch::Tensor depth_logits;  // [B, N, H, W] float32 with depth_bins = N >= 2, else undefined
  // With fuse_defocus_reader in eval mode, the two readings depth_m fuses,
  // each alone [B, 1, H, W] metres: the head's and the filtered reader's
  // (depth_fusion.h); undefined otherwise.
  torch::Tensor network_depth_m, reader_depth_m;
};

class HsdNetImpl : public torch::nn::Module {
 public:
  // upsampling_weights [L, C] (spectral_upsampling_weights of the camera's Ω).
  HsdNetImpl(const NetOptions& options, const torch::Tensor& upsampling_weights);
  // image [B, 3, H, W] (linear sensor RGB) -> cube and depth. With the
  // pre-inversion on, `preinverse` [B, 3K, H, W] is its input beside the image;
  // undefined: computed from the image (preinverse(image)).
  // With residual_spectral_wiener, `base` [B, L, H, W] is the residual's base
  // (undefined: spectral_wiener(image)). With fuse_defocus_reader in eval mode,
  // `reader_cost` [B, K, H, W] is the fused reader's cost volume
  // (undefined: fusion_reader_cost(image)); like the other two, its owner may
  // compute it on a larger window and crop it, so the reader sees the scene
  // around a patch.
  NetOutput forward(const torch::Tensor& image, const torch::Tensor& preinverse = {}, const torch::Tensor& base = {},
                    const torch::Tensor& reader_cost = {});
  // The RGB PSFs [K, 3, P, P] of the pre-inversion's layers (camera_rgb_psfs);
  // set by the owner before forward whenever the optics change (they may carry
  // a gradient to the DOE). Not a parameter or buffer: the optics own them.
  void set_preinverse_psf(const torch::Tensor& rgb_psf);
  const torch::Tensor& preinverse_psf() const { return preinverse_psf_; }
  // image [B, 3, H, W] -> its Wiener deconvolutions [B, 3K, H, W].
  torch::Tensor preinverse(const torch::Tensor& image) const;
  // The spectral Wiener base (residual_spectral_wiener): its prior (mean [L],
  // covariance [L, L], noise variance σ², the camera response omega [3, L]),
  // kept as buffers (so checkpoints and exports carry them), and the band
  // PSFs [L, K, P, P] of the current optics (set like set_preinverse_psf).
  void set_spectral_prior(const torch::Tensor& mean, const torch::Tensor& covariance, double noise_var,
                          const torch::Tensor& omega);
  void set_band_psf(const torch::Tensor& psf);
  // The classical cost volume input (NetOptions::defocus_cost): image [B, 3, H, W] -> [B, K, H, W];
  // no gradient, except through the image with defocus_cost_gradient.
  torch::Tensor defocus_input(const torch::Tensor& image) const;
  // The fused reader's costs (NetOptions::fuse_defocus_reader): image [B, 3, H, W] ->
  // [B, K, H, W] float32, the spectral cost volume over fusion.reader_box_px
  // (depth_fusion.h) less its mean over the layers (the argmin ignores it; the
  // filter's float32 sums stay small), as the exported reconstructor computes it. No gradient.
  torch::Tensor fusion_reader_cost(const torch::Tensor& image) const;
  // The spectral reader's depth: image [B, 3, H, W], guide [B, 1, H, W]
  // (fusion_guide of the cube), its costs [B, K, H, W] (undefined:
  // fusion_reader_cost(image)) -> [B, 1, H, W] metres, float32, no gradient.
  torch::Tensor reader_depth(const torch::Tensor& image, const torch::Tensor& guide, const torch::Tensor& cost = {}) const;
  const torch::Tensor& band_psf() const { return band_psf_; }
  // The prior in the buffers (float32; its psd_exponent the default).
  SpectralPrior spectral_prior() const { return {sw_mean_, sw_cov_, sw_noise_var_.item<double>()}; }
  // The per-illuminant moments of the illuminant reader (read_illuminant; the
  // owner's, from the training scenes, as the buffers' prior; not buffers,
  // so checkpoints of either setting load under the other).
  void set_illuminant_moments(const IlluminantMoments& m);
  // Turns the reader off (the buffers' equal-weight prior), for an owner
  // that has no training reflectance to give it moments from.
  void disable_illuminant_reader() { opt_.read_illuminant = false; }
  const IlluminantMoments& illuminant_moments() const { return illum_; }
  // image [B, 3, H, W] -> the reader's posterior over the illuminants [B, K]
  // (float64), with the band energies of the current band PSFs.
  torch::Tensor illuminant_posterior(const torch::Tensor& image) const;
  // The prior the spectral Wiener base uses for image [1, 3, H, W]: the
  // buffers' in training mode or without read_illuminant, else the posterior
  // mixture.
  SpectralPrior prior_for(const torch::Tensor& image) const;
  // image [B, 3, H, W] -> the spectral Wiener cube [B, L, H, W] (float32).
  // The filter (the OTFs and, with the buffers' prior, the per-frequency
  // solve) is kept while the band PSFs, the prior and the image size stay the
  // same (TensorSnapshot): from the second call on, a frozen design's
  // training steps and a validation's batches reuse it (the same arithmetic,
  // so bitwise the same cube). Not kept while the PSFs carry a gradient.
  torch::Tensor spectral_wiener(const torch::Tensor& image) const;
  const NetOptions& options() const { return opt_; }
  // The residual's spectral-upsampling weights [L, C] (a buffer, or a
  // parameter when learned_spectral_map; "upsampling_weights" either way).
  const torch::Tensor& upsampling_weights() const { return weights_; }
  // Residual learning from the trivial answers: zeroes the cube head (the cube
  // is then the spectral upsampling alone) and the depth head's weights, and
  // sets its bias so every pixel's depth is 1 / inv_depth_per_m (clamped into
  // the head's range); zeroes the refiner's head too (refine_width > 0).
  // Gradients reach the decoders from the first update on.
  void start_at_baselines(double inv_depth_per_m);
  // Data-parallel training: batch statistics over all replicas (nullptr: this process's batch).
  void set_replica_group(const std::shared_ptr<ReplicaGroup>& group);

 private:
  // The spectral reader's cost volume with the network's band PSFs and prior
  // (checks they are set and have K = layer_depths_m.size() depths): [B, K, H, W],
  // differentiable in the image alone (callers that want no gradient pass it detached).
  torch::Tensor spectral_reader_cost(const torch::Tensor& image, int64_t window_px) const;
  torch::nn::Sequential block(int64_t in, int64_t out);
  // One block or layer in the dtype of x (float32 or bfloat16, see above).
  torch::Tensor run_block(torch::nn::Sequential& block, torch::Tensor x) const;
  torch::Tensor run_conv(torch::nn::Conv2d& conv, const torch::Tensor& x) const;
  NetOptions opt_;
  std::vector<torch::nn::Sequential> down_;
  torch::nn::Sequential bottom_{nullptr};
  std::vector<torch::nn::Conv2d> up_hs_, up_depth_;
  std::vector<torch::nn::Sequential> dec_hs_, dec_depth_;
  torch::nn::Conv2d head_hs_{nullptr}, head_depth_{nullptr};
  CubeRefiner refiner_{nullptr};  // refine_width > 0
  torch::Tensor weights_;  // buffer [L, C]
  torch::Tensor preinverse_psf_;  // [K, C, P, P] or undefined
  torch::Tensor band_psf_;        // [L, K, P, P] or undefined
  torch::Tensor sw_mean_, sw_cov_, sw_noise_var_, sw_omega_;  // buffers (residual_spectral_wiener)
  // spectral_wiener's filters and what they were made from. A filter is kept
  // on the second call with the same inputs (a trained design's PSFs change
  // every step and would only hold memory); the OTFs, for the per-image
  // priors of read_illuminant, when at most kMaxKeptOtfBytes.
  struct WienerKeep {
    TensorSnapshot psf, mean, cov, noise, omega;
    int64_t H = -1, W = -1;
    std::shared_ptr<SpectralWienerFilter> filter;
    std::shared_ptr<SpectralOtf> otf;
  };
  static constexpr int64_t kMaxKeptOtfBytes = int64_t(32) << 20;
  mutable WienerKeep sw_keep_;
  // project_residual's filter, for the network's view (its own size).
  mutable WienerKeep proj_keep_;
  // The buffers' filter for H × W cubes, kept in proj_keep_ while the band
  // PSFs, the prior and the size stay the same (and no gradient needs it).
  SpectralWienerFilter projection_filter(int64_t H, int64_t W) const;
  // The OTFs of the band PSFs for H × W images (sw_keep_ is theirs), kept or made.
  SpectralOtf kept_otf(int64_t H, int64_t W) const;
  IlluminantMoments illum_;  // read_illuminant
};
TORCH_MODULE(HsdNet);

}  // namespace hsd::model
