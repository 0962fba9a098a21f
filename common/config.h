// Typed, validated experiment configuration. JSON is parsed here, once, at the
// edge; the libraries below only ever see these structs. Units are in the key
// names (SI unless the name says otherwise: *_m metres, *_nm nanometres).
// The keys named in docs/formats.md keep their meaning; see configs/base.json for
// every key with its default.
#pragma once
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "common/choices.h"
#include "common/json_reader.h"

namespace hsd {

struct DoeConfig {
  // "fresnel" | "spiral" | "fisher" | "flat" | "random" | "file:PATH"
  DoeFamily init = DoeFamily::fresnel;
  std::string init_path;  // the height-map file of init = "file:PATH"
  // Largest height [m]; 0 means one 2π period at the design wavelength,
  // design_wavelength_m / (n(design_wavelength_m) - 1).
  double max_height_m = 0.0;
  double design_wavelength_m = 550e-9;  // λ0 of the fresnel/spiral families [m]
  double design_depth_m = 0.0;          // z0 [m]; 0 = middle of depths_m in inverse depth
  int64_t quantization_levels = 0;      // K height levels (straight-through gradient); 0 = continuous
  int64_t spiral_wings = 3;             // wings of the spiral (diffracted-rotation) DOE
  std::string fisher_path = "out/fisher/fisher_height.pt";  // used by init = "fisher"
};

struct OpticsConfig {
  std::vector<double> wavelengths_nm;  // band centres [nm], strictly increasing
  double band_width_nm = 0.0;          // 0 = spacing of wavelengths_nm (10 nm for one band)
  std::vector<double> depths_m;        // point-source / depth-layer distances from the DOE [m]
  double sensor_distance_m = 0.05;     // DOE to sensor [m]
  double pixel_pitch_m = 6.22e-6;      // sensor pixel pitch [m]
  double aperture_diameter_m = 2.0e-3; // circular (or square side) aperture on the DOE [m]
  ApertureShape aperture_shape = ApertureShape::circle;  // "circle" | "square"
  int64_t psf_size = 63;               // odd PSF window [pixels]
  double doe_pitch_m = 4e-6;           // DOE sample pitch [m]
  int64_t doe_samples = 512;           // DOE samples across the (square) grid
  std::string material = "fused_silica_malitson1965";  // key in data/spectra/refractive_index_materials.json
  int64_t pixel_quadrature_nodes = 0;  // Gauss-Legendre nodes per pixel and axis; 0 = auto per wavelength
  double pixel_quadrature_tol = 1e-1;  // per-Fourier-component bound of the auto rule (optics/pixel_quadrature.h)
  FloatPrecision precision = FloatPrecision::float32;  // "float32" | "float64" (phases are always built in float64)
  // "store": autograd keeps every band's intermediates (fastest); "recompute":
  // keep only the height map and recompute each band in the backward pass (lean).
  PsfBackward psf_backward = PsfBackward::store;
  // Relative singular-value cut of the low-rank window kernels (optics/fresnel_mft.h); 0 = exact MFT.
  double mft_rank_tol = 1e-4;
  // Sub-samples of the pupil per DOE cell and axis: each cell of constant height
  // is evaluated at k×k points (1 = one point per cell).
  int64_t pupil_oversampling = 1;
  // How each DOE cell is integrated (optics/fresnel_mft.h): "sinc_cross" (the smooth phases'
  // linear part across the cell, with the cross term), "sinc" (without it), "midpoint" (cell centres).
  CellIntegration pupil_cell_integration = CellIntegration::sinc_cross;
  // Wavelengths per band (Gauss–Legendre across the band, flat spectrum inside it):
  // the band's PSF is their weighted mean. 1 = the band centre only (the paper's
  // model: 4.8% worst PSF error on its 10-nm bands; 2 nodes: 1.2%, hsd_bench accuracy).
  int64_t spectral_samples = 2;
  double energy_warn_threshold = 0.5;  // warn when energy_in_window of a (λ, z) falls below this
  // Where the imaging PSFs come from: "simulator" (the DOE's, optics/psf.h) or
  // "all_in_focus" (the control with no optical cue, optics/all_in_focus.h: one
  // diffraction-limited in-focus PSF for every band and depth; the DOE is unused
  // and the network alone is trained), or "file:PATH" (a psf.pt, optics/psf_file.h:
  // measured by hsd_calibrate or from another tool; its wavelengths, depths,
  // pixel pitch and window must be the config's; the DOE is unused and the
  // network alone is trained, e.g. fine-tuned from train.init_checkpoint).
  PsfSource psf_source = PsfSource::simulator;
  std::string psf_path;  // the PSF file of psf_source = "file:PATH"
  // The point source's angle from the optical axis in the x-z plane [degrees]:
  // hsd_psf then computes the off-axis PSF (optics/off_axis_psf.h: the window
  // centred on the chief ray's image point −s tan θ) and the shift-variance
  // table against the on-axis PSF. Training and imaging are on-axis (the
  // shift-invariant model) and refuse a non-zero angle.
  double field_angle_deg = 0.0;
  DoeConfig doe;

  std::vector<double> wavelengths_m() const;
  double band_width_m() const;
};

struct SensorConfig {
  std::string camera = "canon_5d_mark_iii";  // data/spectra/camera_sensitivity_<camera>.csv
  // Additive Gaussian read noise: σ drawn per image uniformly from
  // [noise_std_min, noise_std] (relative to saturation = 1); 0 disables it.
  double noise_std = 0.0;
  double noise_std_min = -1.0;               // < 0: same as noise_std (a fixed σ)
  double photons_at_saturation = 0.0;        // shot noise as N(J, J/photons); 0 disables it
  double saturation = 1.0;                   // clip J to [0, saturation]; 0 disables clipping
  int64_t bit_depth = 0;                     // quantize to 2^bits − 1 levels (straight-through); 0 = off
  double mask_sigma_px = 1.0;                // Gaussian σ of the soft layer masks M_z [pixels]
  Compositing compositing = Compositing::linear;  // "linear" (the paper's model) | "occlusion" (Ikoma et al. 2021)
  std::string illuminant = "D65";            // column of data/spectra/illuminants.csv, for reflectance scenes
};

// Fisher-information / CRLB DOE design (optics/fisher.h, hsd_fisher).
struct FisherConfig {
  double photons = 1e4;               // signal photons per point-source image
  double background = 10.0;           // background photons per pixel
  int64_t window_px = 31;             // PSF window of the Fisher computation (odd)
  int64_t pixel_nodes = 2;            // Gauss–Legendre nodes per pixel axis
  int64_t design_samples = 256;       // DOE samples across the grid during the design (0 = optics.doe_samples)
  int64_t wavelength_stride = 6;      // use every k-th configured band (and the last)
  int64_t depth_stride = 1;           // every k-th configured depth (and the last)
  FisherBasis basis = FisherBasis::zernike;  // "zernike" | "freeform"
  int64_t zernike_modes = 36;         // Noll modes 2..(modes+1)
  FisherStart start = FisherStart::fresnel;  // "fresnel" (unwrapped lens) | "flat"
  int64_t steps = 100;
  double lr = 0.02;                   // Adam: micrometres of Zernike coefficient (zernike) or of height (freeform)
  // Unknown besides (1/z, λ), eliminated by the Schur complement (optics/fisher.h):
  // "x", "y" (the point's lateral position), "N" (its brightness); [] = both known.
  std::vector<NuisanceParam> nuisance{NuisanceParam::x, NuisanceParam::y, NuisanceParam::N};
  // How the per-point bounds become one number (and the design's objective):
  // "capped_mean" (each point capped at aggregate_cap), "median", "mean" (the earlier one).
  CrlbAggregate aggregate = CrlbAggregate::capped_mean;
  double aggregate_cap = 10.0;        // layers/bands
  // What the bound is for (optics/scene_fisher.h): "point" a point source of
  // known spectrum (Shechtman et al., the paper's Fisher design); "scene" a
  // 1/f² Gaussian texture seen in the camera's RGB channels (only the MTF
  // carries depth; the bound of 1/z alone, "N" in nuisance = contrast unknown).
  FisherModel model = FisherModel::point;
  double scene_noise_variance = 1e-3;  // scene: white noise relative to the texture's variance
  int64_t scene_patch_px = 64;         // scene: the bound is for a patch of this many pixels squared
};

// The reconstruction network (model/unet.h).
struct ModelConfig {
  int64_t base_width = 32;      // channels of the first U-Net level, doubled per level
  int64_t levels = 4;           // poolings (inputs are padded to multiples of 2^levels)
  NormKind norm = NormKind::batch;  // "batch" | "group" | "none"
  // The depth head's sigmoid spans the depth range widened by this fraction of
  // its inverse-depth span at each end, so the nearest and farthest targets do
  // not ask for a saturated sigmoid (0 = exactly the range, the paper's form).
  double depth_margin = 0.1;
  // "baselines": the output heads start at the two trivial answers (cube head
  // zero, so the cube is the spectral upsampling; depth head constant at the
  // training split's median inverse depth), so training starts at the
  // baselines and every step is measured from them. "random": torch's default
  // initialisation of the heads (the paper's code).
  HeadInit head_init = HeadInit::baselines;
  // "wiener": the sensor image's Wiener deconvolution with every depth layer's
  // RGB PSF is input beside it (model/wiener_preinverse.h; 3 channels per
  // layer of optics.depths_m), computed from the current DOE each step.
  // "none": the image alone (the paper's network).
  Preinverse preinverse = Preinverse::none;
  double preinverse_reg = 1e-2;  // the Wiener regulariser ρ (noise-to-signal power)
  // What the cube head's output is added to: "image", the spectral upsampling
  // of the sensor image (the paper's residual); "preinverse", the spectral
  // upsampling of the mean of the layers' Wiener deconvolutions (needs
  // preinverse = "wiener"): a sharper start the network refines;
  // "spectral_wiener", the LMMSE cube of the image under the training
  // split's spectral statistics (model/spectral_wiener.h), no spectral map.
  ResidualBase residual = ResidualBase::image;
  // The residual base's spectral upsampling (model/spectral_upsampling.h):
  // "fixed", the paper's map from the camera response Ω; "learned", the same
  // [L, 3] linear map as a network parameter started at the paper's, scored
  // alone by hsd_eval (model_base_*). Measured, not adopted: docs/learning.md,
  // "The cube's gain and the illuminant".
  SpectralMap spectral_map = SpectralMap::fixed;
  // true: the residual's base (the cube the head adds to) is also input to
  // the network beside the image (+L channels), so it sees what it corrects;
  // false: the paper's network. Measured: docs/learning.md, "The network sees
  // the cube it corrects".
  bool base_as_input = false;
  // A classical depth-from-defocus cost volume of the image as more input
  // (model/defocus_likelihood.h; K channels, the per-layer negative
  // log-likelihood less its mean over the layers): "grey" needs preinverse =
  // "wiener" (its RGB PSFs), "spectral" needs residual = "spectral_wiener" (its
  // prior and band PSFs). Measured: docs/learning.md, "A classical reader of the cue".
  DefocusCost defocus_cost = DefocusCost::none;
  // true (needs defocus_cost = "spectral"): that cost volume is differentiable
  // in the sensor image, so the depth term reaches the DOE through it as
  // through the image (not through its PSFs); false: no gradient through it.
  // Measured: docs/learning.md, "The reader's costs as input at the cube's end".
  bool defocus_cost_gradient = false;
  // true (needs residual = "spectral_wiener"): in evaluation (and in the
  // exported reconstructor) the depth output fuses the network's depth with
  // the spectral depth-from-defocus reader's (model/depth_fusion.h); training
  // is unchanged. Measured: docs/learning.md, "The reader's window, and an
  // edge-aware aggregation".
  bool fuse_defocus_reader = false;
  // The fusion's settings: the reader's energy box (odd, px), the guided
  // filters' radii of its costs and of the averaged depth (px; 0 = none) and
  // their ε (relative to the guide's mean squared). 31, 0, 0: the plain mean
  // with the reader over a 31-px box, the fusion's first form.
  int64_t fusion_reader_box_px = 7;
  int64_t fusion_cost_radius_px = 7;
  int64_t fusion_depth_radius_px = 4;
  double fusion_guide_eps = 0.1;
  // true (needs residual = "spectral_wiener" and reflectance training scenes):
  // in evaluation (and validation, and the exported reconstructor) the
  // spectral Wiener base uses the spectral prior mixed under the posterior of
  // the training illuminants given each image (model/illuminant_reader.h),
  // not the equal-weight mixture; the readers of depth and training are
  // unchanged. Its block means' side (px)
  // and the number of independent blocks the likelihood counts as.
  bool read_illuminant = false;
  int64_t illuminant_block_px = 16;
  double illuminant_effective_blocks = 32;
  // > 0 (needs residual = "spectral_wiener"): in evaluation (and validation)
  // the spectral Wiener base becomes the cube with a total-variation edge
  // prior of this weight (model/spectral_tv.h; radiance units), solved by
  // half-quadratic splitting over edge_prior_iterations steps of ρ̃ from
  // edge_prior_rho_start growing ×edge_prior_rho_factor; training is
  // unchanged. 0 = the linear cube. Measured: docs/learning.md, "An edge prior for the cube".
  double edge_prior_weight = 0.0;
  int64_t edge_prior_iterations = 8;
  double edge_prior_rho_start = 1e-3;
  double edge_prior_rho_factor = 2.0;
  // true (needs residual = "spectral_wiener"): the cube head's residual is
  // added through (I − W H̄), the part of it the image does not determine
  // (model/spectral_wiener.h, spectral_wiener_unobserved). Measured:
  // docs/learning.md, "The residual off what the image fixes".
  bool project_residual = false;
  // > 0: a second stage refines the cube, a U-Net of this base width reading
  // the image and the first stage's cube (model/cube_refiner.h); 0 = one
  // stage. Measured: docs/learning.md, "A second stage for the cube".
  int64_t refine_width = 0;
  // The depth head: 0 = a sigmoid (the paper's); N >= 2 = a soft argmax over N
  // bins of normalised inverse depth (model/unet.h).
  int64_t depth_bins = 0;
};

// The errors a fab makes, applied to a DOE height map (optics/fabrication_error.h):
// hsd_calibrate --make-captures images a DOE perturbed by them; as
// train.fabrication_noise they are the scales of random errors drawn each step.
struct FabricationErrorConfig {
  double height_scale_error = 0.0;       // relative etch-depth error: h -> (1 + e) h
  double roughness_rms_m = 0.0;          // random height error, RMS [m]
  double roughness_correlation_m = 0.0;  // its correlation length (Gaussian σ) [m]; 0 = white (per DOE sample)
  double edge_blur_m = 0.0;              // Gaussian σ of the height map's blur (edge rounding) [m]
  double misalignment_m = 0.0;           // lateral offset of each level's mask k >= 1 against mask 0 [m] (needs fabrication.levels)
  double decentre_m = 0.0;               // lateral offset of the whole DOE against the aperture (along +x) [m]
};

// Joint training of DOE and network (train/trainer.h).
struct TrainConfig {
  int64_t steps = 1000;
  int64_t batch_size = 4;
  double lr_net = 5e-4;             // Adam, network parameters
  double lr_doe_m = 2e-9;           // Adam, DOE height (metres per step at full rate)
  int64_t warmup_steps = 50;        // linear warm-up of both rates
  LrDecay decay = LrDecay::cosine;  // "cosine" (to min_lr_ratio at the last step) | "none"
  double min_lr_ratio = 0.05;
  double clip_grad_norm = 1.0;      // the network's gradient norm (not the DOE's); 0 = off
  // Scene context [px] the network sees around each training or validation
  // patch, on every side: its input is the centre (patch + 2 c) of the
  // rendered window and its outputs are cropped back to the patch before the
  // loss, so every scored pixel has c px of the scene beside it, as in a whole
  // scene. 0 = the network sees the patch alone (the paper's); at most
  // data.render_margin_px (the rendered reach). Evaluation is unchanged.
  int64_t network_context_px = 0;
  // Exponential moving average of the trained weights (network and DOE), the
  // model that validation, checkpoints and evaluation use (Polyak averaging):
  // after step k, w̄ ← d_k w̄ + (1 − d_k) w with d_k = min(ema_decay, (1+k)/(10+k)).
  // 0 = off (the model is the last step's weights).
  double ema_decay = 0.0;
  // model.residual = "spectral_wiener": whether the DOE learns through the
  // filter of the cube's residual base (its gradient into the band PSFs);
  // false: the filter is the current DOE's, without that gradient, and the
  // DOE learns through the sensor image alone. That gradient is ~21 % of the
  // quick config's step (docs/benchmarks.md).
  bool spectral_wiener_doe_gradient = true;
  // model.preinverse = "wiener": whether the DOE learns through the
  // pre-inversion's filters (their gradient into the layers' RGB PSFs); false:
  // the filters are the current DOE's, without that gradient (the forward
  // pass is the same).
  bool preinverse_doe_gradient = true;
  bool freeze_doe = false;          // fixed-DOE ablations
  // The DOE's gradient is taken and its Adam step made on steps 0, N, 2N, ...
  // only; the steps between train the network alone, on images rendered
  // through the current design's kept PSFs (no PSF forward, and no backward
  // into the network's inputs, the sensor image or the PSFs: the frozen
  // design's step). 1 = every step (the paper's joint training). lr_doe_m is
  // the rate of the steps that update the DOE, as given.
  int64_t doe_every = 1;
  // β₁ of the DOE's Adam (the decay of its first moment, the gradient's
  // running mean); the network's stays at 0.9. The DOE's gradient is mostly
  // noise step to step (docs/learning.md): a larger β₁ averages it over
  // about 1/(1 − β₁) steps before it moves the design, at the same drift per
  // step for a steady gradient. 0.9 = LibTorch's default, the paper's.
  double doe_adam_beta1 = 0.9;
  // Scale of the cube term's gradient into the DOE through the spectral Wiener
  // base (model.residual = "spectral_wiener"): the cube is base + the U-Net's
  // residual, and the base is the filter applied to the sensor image, so the
  // cube term reaches the design through the image along two paths. k
  // multiplies the one through the base (the linear estimate) alone; the
  // base depends on no network parameter, so the network trains as at 1. Lets
  // the design weight the cube more than the shared encoder does
  // (docs/learning.md). 1 = the paper's single loss.
  double base_doe_gradient_scale = 1.0;
  // A training checkpoint whose network weights start this run (fine-tuning,
  // e.g. on measured PSFs); "" = the network's own initialisation. Only the
  // network is taken: the DOE, the optimizer state and the step start afresh.
  std::string init_checkpoint;
  double loss_alpha = 1.0, loss_beta = 1e-2, loss_gamma = 1e-2;  // L1 cube, L1 inverse depth, TV of predicted inverse depth
  // The depth term: "inverse_l1" (|1/Ẑ − 1/Z|, the paper), "metric_l1"
  // (|Ẑ − Z| in metres, the unit the evaluation reports) or "metric_l2"
  // ((Ẑ − Z)² in m², the evaluation's RMSE squared: train/loss.h).
  DepthLoss depth_loss = DepthLoss::inverse_l1;
  // The cube term: "l1" (mean |Î − I|, the paper) or "l2" (mean (Î − I)², the
  // error PSNR measures; minimised by the conditional mean, where L1 takes the
  // median: train/loss.h). loss_alpha weights either.
  HsLoss hs_loss = HsLoss::l1;
  // Weight of the depth bins' cross-entropy against two-hot targets (train/loss.h);
  // > 0 needs model.depth_bins >= 2.
  double depth_ce_weight = 0.0;
  // With the cube's second stage (model.refine_width > 0): weight of the cube
  // term on the first stage's cube x₁ as well, relative to the final cube's
  // (deep supervision: α·(e₂ + w·e₁)); 0 = the final cube alone.
  double first_stage_cube_weight = 0.0;
  int64_t val_every = 100;          // steps between validations (and the last step)
  int64_t val_patches = 8;          // fixed validation patches from the val split
  int64_t checkpoint_every = 100;   // steps between checkpoints (and the last step)
  int64_t log_every = 10;           // steps between metrics.csv rows
  // The network's arithmetic in training steps (model/unet.h): "float32" (the
  // default: bfloat16's validation curves did not match float32's on the
  // quick config, docs/training.md), "bfloat16" (convolutions in bfloat16,
  // float32 master weights, optimizer, norms and loss), or "auto" (bfloat16 on
  // a CPU with native bfloat16 arithmetic, float32 elsewhere). Validation,
  // evaluation and the optics are float32 whatever this says.
  TrainPrecision precision = TrainPrecision::float32;
  // Fabrication-aware training (optics/fabrication_error.h): each step the
  // height map the optics see is the DOE perturbed by random errors of these
  // scales (etch depth e ~ N(0, height_scale_error²), new roughness of this
  // RMS, edge blur σ ~ U(0, edge_blur_m), decentre ~ U(0, decentre_m) in a
  // random direction); the gradient flows through the errors to the DOE
  // (docs/fabrication.md says why not straight through).
  // All 0 = off. misalignment_m must be 0 (it needs the level masks).
  FabricationErrorConfig fabrication_noise;
  // A curriculum: the scales grow linearly from 0 at step 0 to fabrication_noise
  // at this step (the draws scaled, so step k's errors are (k / ramp) times the
  // full run's); 0 = the full scales from the first step.
  int64_t fabrication_noise_ramp_steps = 0;
  // true: under fabrication_noise the network's linear inputs (pre-inversion,
  // spectral Wiener filter) are built from the perturbed surface's PSFs, as a
  // camera calibrated after fabrication has them; false: from the design's.
  bool fabrication_noise_calibrated = false;
};

// Data-parallel training over several processes (train/distributed.h); who
// takes part comes from torchrun's environment variables, not the config.
struct DistributedConfig {
  double timeout_s = 300.0;  // rendezvous and every collective: a dead or stalled rank ends the others after this
  double bucket_mib = 25.0;  // gradients are summed in flat buckets of about this size (fewer, larger collectives)
  bool sync_batch_norm = true;  // batch statistics of the global batch (matches one process); false: per rank, as DDP
  bool split_psf = true;        // training PSFs computed once, shared out by bands (train/shared_psf.h); false: every rank all
};

// hsd_fabricate --tolerance: the error sizes swept, one kind at a time (each
// list starts at 0, the fabricated design without error).
struct FabricationToleranceConfig {
  std::vector<double> height_scale_error{0.0, 0.025, 0.05, 0.1, 0.2};
  std::vector<double> roughness_rms_m{0.0, 5e-9, 10e-9, 20e-9, 40e-9};      // swept white and correlated
  double roughness_correlation_m = 16e-6;                                    // σ of the correlated sweep [m]
  std::vector<double> misalignment_m{0.0, 0.5e-6, 1e-6, 2e-6, 4e-6};
  std::vector<double> edge_blur_m{0.0, 1e-6, 2e-6, 4e-6, 8e-6};
  std::vector<double> decentre_m{0.0, 10e-6, 20e-6, 50e-6, 100e-6};
  // Each DOE cell is rendered as s x s sub-cells, so lateral errors move
  // edges by steps of doe_pitch_m / s (the cells' heights are unchanged).
  int64_t subsamples = 4;
  bool network = true;  // with a checkpoint and its data: HS PSNR and depth RMSE at every size (the test split)
  // true: the network's linear inputs (pre-inversion, spectral Wiener filter) and the
  // Wiener baselines use each fabricated surface's PSFs (a camera calibrated after it
  // was made); false: the design's PSFs, as trained.
  bool calibrated = false;
  // Random draws of the errors together, drawn as train.fabrication_noise
  // draws them from draw_scales (etch σ 10 %, correlated roughness 20 nm over
  // 16 µm, edge blur σ ~ U(0, 8 µm): configs/quick_fab_robust.json's noise):
  // the mean loss under a fab's errors. The draws depend on their index only,
  // so every DOE and run meets the same ones. 0 = off.
  int64_t draws = 8;
  FabricationErrorConfig draw_scales{0.1, 20e-9, 16e-6, 8e-6, 0.0, 0.0};
};

// hsd_fabricate: the K-level lithography of a height map (optics/lithography.h).
struct FabricationConfig {
  int64_t levels = 16;                 // K height levels, a power of two: log2 K binary masks
  double min_feature_m = 4e-6;         // the smallest line or space the process makes [m]; smaller ones are flagged
  std::string cell_name = "HSD_DOE";   // the GDSII top cell
  FabricationErrorConfig error;
  FabricationToleranceConfig tolerance;
};

// Synthetic point-source captures (hsd_calibrate --make-captures): what a lab
// bench would record through the (perturbed) DOE, in 16-bit sensor counts.
struct SyntheticCaptureConfig {
  int64_t frame_px = 0;                // square frame [px]; 0 = 4 * optics.psf_size + 1
  double peak_counts = 40000.0;        // exposure: the brightest pixel of each slice's PSF at this many counts
  double background_counts = 200.0;    // stray light, counts per pixel (Poisson; in the dark frames too: they are taken with the source off)
  double dark_counts = 100.0;          // dark level, counts per pixel (in the dark frame too)
  double read_noise_counts = 3.0;      // Gaussian read noise σ [counts]
  int64_t hot_pixels = 20;             // hot pixels per frame (the same pixels in every frame and the dark)
  int64_t exposures = 4;               // frames per slice (and dark frames), averaged by the calibration
  std::vector<double> axis_offset_px{0.37, -0.21};  // the optical axis from the frame centre, (row, col) [px]
  int64_t seed = 0;                    // of the noise and hot pixels (the roughness follows the top-level seed)
};

// hsd_calibrate: measured PSFs from point-source captures (optics/psf_calibration.h).
struct CalibrationConfig {
  // "auto": register to captures.json's axis_px when it gives one, else to each
  // slice's centroid; "centroid": every slice centred on its centroid
  // (docs/formats.md); "axis": every slice on axis_px (required).
  Registration registration = Registration::automatic;
  // The background under the PSF: "auto" ("dark" when captures.json gives
  // dark frames, else "ring"); "dark": the dark frames (taken with the source
  // off: dark current and stray light) are the whole background; "ring": also
  // subtract the median of the frame's outer ring (which holds any light the
  // DOE scatters that far: biased for wide-angle scatter, docs/camera.md).
  CaptureBackground background = CaptureBackground::automatic;
  double hot_pixel_sigma = 8.0;   // a hot pixel is this many noise σ above its neighbours' median ...
  double hot_pixel_ratio = 3.0;   // ... and this many times its brightest neighbour
  double min_snr = 10.0;          // a capture whose peak is below this many noise σ holds no signal (exit 2)
  SyntheticCaptureConfig synthetic;
};

// hsd_scenes: synthetic tabletop HS-D scenes (data/scene_generator.h).
struct GeneratorConfig {
  int64_t train_scenes = 12, val_scenes = 2, test_scenes = 2;
  int64_t width_px = 512, height_px = 384;
  double fov_deg = 40.0;                       // horizontal field of view of the generator's pinhole camera
  double depth_min_m = 0.4, depth_max_m = 2.5;  // nearest object surface .. back wall
  int64_t objects_min = 3, objects_max = 7;
  bool colorchecker = true;                     // also write the 24-patch ColorChecker scene (test split)
  double colorchecker_depth_m = 1.0;
  bool half = true;                             // spectral channels as 16-bit floats
  // Scene layouts and their weights (data/textured_scene.h): "tabletop" (textured
  // room geometry), "dead_leaves" (occluding textured shapes over the whole depth
  // range), "classic_tabletop" (the flat-coloured generator of earlier results,
  // ColorChecker-derived spectra; {"classic_tabletop": 1} reproduces it exactly).
  std::vector<std::pair<SceneLayout, double>> layouts{{SceneLayout::dead_leaves, 0.5}, {SceneLayout::tabletop, 0.5}};
  std::string texture_dir;                       // photographs for textures; "" = the shipped data/textures
  double texture_scale_min = 0.25, texture_scale_max = 1.25;  // scene pixels per texture pixel (log-uniform)
  // "area": each scene pixel averages the photo over its footprint, as a sensor
  // pixel integrates (no aliasing where a pixel spans several photo pixels);
  // "point": one bilinear sample per pixel, which aliases (the default while
  // the documented results are those of point-sampled scenes; docs/data.md).
  TextureFilter texture_filter = TextureFilter::point;
  int64_t dead_leaves_max_shapes = 4000;         // upper bound on the shapes of one dead-leaves scene
  // Dead-leaves radii follow p(r) ∝ r⁻³ on [min, max] · min(H, W) (min >= 1.5 px).
  double dead_leaves_min_radius = 0.02;
  double dead_leaves_max_radius = 0.5;
  // > 0: the leaves are surface markings on larger occluding surfaces (the same
  // r⁻³ law on [this, max] · min(H, W)) that carry the depth, so depth edges are
  // fewer than colour edges, as in real scenes (data/depth_structure.h);
  // 0: every leaf is its own surface at its own depth (hsd before the depth
  // structure was measured: dead leaves 0.82 against real maps 0.31-0.77).
  double dead_leaves_surface_min_radius = 0.2;
  double spectral_exclusion = 0.05;              // measured spectra whose shape is this close to a ColorChecker patch are dropped
};

// The 29 CIE illuminants of the spectral augmentation (data/illuminant_augment.h
// says why these): incandescent A, daylight D50-D75, fluorescent FL1-FL12,
// high-pressure HP1-HP5, white LEDs LED-B1-B5, LED-BH1, LED-RGB1.
std::vector<std::string> default_augmentation_illuminants();

struct DataConfig {
  std::string root = "out/data";
  bool generate_if_missing = true;    // hsd_train: run the generator when root has no manifest.json
  std::vector<std::string> illuminants = default_augmentation_illuminants();
  double intensity_min = 0.5, intensity_max = 1.0;  // random global scale of the lit radiance
  int64_t patch_size_px = 256;
  // Scene context rendered around each training patch [px] so the patch's
  // sensor image holds the light its surroundings blur into it (the network
  // and the loss see the centre patch_size_px only); -1 = the PSF's and the
  // soft layer masks' reach, optics.psf_size / 2 + ceil(3 sensor.mask_sigma_px);
  // 0 = none (the patch's own edges replicated outward).
  int64_t render_margin_px = -1;
  // true: training and validation windows may reach past a scene's border by
  // the rendering margin, the scene continued by its replicated edge as the
  // whole-scene renderer continues it, so patches (and the loss) cover the
  // border band that evaluation scores too; false: every window inside the
  // scene, so no patch centre comes within the margin of the border.
  bool border_patches = false;
  int64_t loader_threads = 0;        // scene loading; 0 = all cores
  GeneratorConfig generator;
};

struct Config {
  uint64_t seed = 0;
  ComputeDevice device = ComputeDevice::cpu;  // "cpu" | "cuda"
  int64_t threads = 0;         // intra-op threads; 0 = all cores
  OpticsConfig optics;
  SensorConfig sensor;
  FisherConfig fisher;
  ModelConfig model;
  TrainConfig train;
  DistributedConfig distributed;
  DataConfig data;
  FabricationConfig fabrication;
  CalibrationConfig calibration;
  Json resolved;  // the fully resolved JSON (after extends and --set), written next to outputs
};

// Parses and validates; InputError naming the key path on any problem,
// including keys that no part of hsd reads. The structs above hold every
// default (one source of them); with unlike_defaults, the dotted paths of the
// scalar keys whose value differs from it are listed there (configs/base.json
// has none: tests/common/test_config.cpp).
Config parse_config(const Json& resolved, std::vector<std::string>* unlike_defaults = nullptr);
// load_json_with_extends(path), apply every "--set" override, parse_config.
Config load_config(const std::string& path, const std::vector<std::string>& overrides);

}  // namespace hsd
