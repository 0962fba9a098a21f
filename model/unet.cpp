#include "model/unet.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "model/conv_block.h"
#include "model/spectral_upsampling.h"
#include "model/sync_batch_norm.h"
#include "model/spectral_wiener.h"
#include "model/wiener_preinverse.h"
#include "model/defocus_likelihood.h"
#include "model/depth_fusion.h"

namespace hsd::model {

namespace F = torch::nn::functional;

namespace {

// A kept filter's prior (HsdNetImpl::WienerKeep's snapshots): the same
// tensors, unwritten since they were remembered.
template <class Keep>
bool holds_prior(const Keep& k, const torch::Tensor& mean, const torch::Tensor& cov, const torch::Tensor& noise,
                 const torch::Tensor& omega) {
  return k.mean.matches(mean) && k.cov.matches(cov) && k.noise.matches(noise) && k.omega.matches(omega);
}
template <class Keep>
void remember_prior(Keep& k, const torch::Tensor& mean, const torch::Tensor& cov, const torch::Tensor& noise,
                    const torch::Tensor& omega) {
  k.mean = TensorSnapshot(mean), k.cov = TensorSnapshot(cov), k.noise = TensorSnapshot(noise);
  k.omega = TensorSnapshot(omega);
}

}  // namespace

torch::nn::Sequential HsdNetImpl::block(int64_t in, int64_t out) { return conv_block(in, out, opt_.norm); }

torch::Tensor HsdNetImpl::run_conv(torch::nn::Conv2d& conv, const torch::Tensor& x) const {
  if (x.scalar_type() == conv->weight.scalar_type()) return conv->forward(x);
  const auto& o = conv->options;
  const torch::Tensor b = conv->bias.defined() ? conv->bias.to(x.scalar_type()) : torch::Tensor();
  // Channels-last weights with channels-last activations: oneDNN's fast path for bfloat16.
  return F::conv2d(x, conv->weight.to(x.scalar_type()).contiguous(torch::MemoryFormat::ChannelsLast),
                   F::Conv2dFuncOptions().bias(b).stride(o.stride()).padding(o.padding()));
}

torch::Tensor HsdNetImpl::run_block(torch::nn::Sequential& block, torch::Tensor x) const {
  if (x.scalar_type() == torch::kFloat32) return block->forward(x);
  const auto dtype = x.scalar_type();
  for (const auto& m : block->children()) {
    if (m->as<torch::nn::Conv2dImpl>()) {
      torch::nn::Conv2d c(std::dynamic_pointer_cast<torch::nn::Conv2dImpl>(m));
      x = run_conv(c, x);
    } else if (m->as<torch::nn::ReLUImpl>()) {
      x = torch::relu(x);
    } else if (auto* gn = m->as<torch::nn::GroupNormImpl>()) {
      x = gn->forward(x.to(torch::kFloat32)).to(dtype);  // statistics in float32
    } else if (auto* bn = m->as<SyncBatchNorm2dImpl>()) {
      x = bn->forward(x.to(torch::kFloat32)).to(dtype);
    } else {
      TORCH_CHECK(false, "HsdNet: no mixed-precision rule for layer ", m->name());
    }
  }
  return x;
}

HsdNetImpl::HsdNetImpl(const NetOptions& options, const torch::Tensor& upsampling_weights) : opt_(options) {
  TORCH_CHECK(opt_.levels >= 1 && opt_.levels <= 8, "levels must be in [1, 8]");
  TORCH_CHECK(opt_.preinverse_layers >= 0 && (opt_.preinverse_layers == 0 || opt_.preinverse_reg > 0),
              "preinverse_layers must be >= 0 and preinverse_reg > 0");
  TORCH_CHECK(!opt_.residual_preinverse || opt_.preinverse_layers > 0,
              "residual_preinverse needs the pre-inversion (preinverse_layers > 0)");
  const int64_t K = int64_t(opt_.layer_depths_m.size());
  TORCH_CHECK(opt_.defocus_cost != DefocusCost::grey || (opt_.preinverse_layers > 0 && K == opt_.preinverse_layers),
              "defocus_cost grey needs the pre-inversion with one layer per entry of layer_depths_m");
  TORCH_CHECK(opt_.defocus_cost != DefocusCost::spectral || (opt_.residual_spectral_wiener && K > 0),
              "defocus_cost spectral needs the spectral Wiener base and layer_depths_m");
  TORCH_CHECK(!(opt_.edge_prior.weight > 0) || opt_.residual_spectral_wiener, "edge_prior needs the spectral Wiener base");
  TORCH_CHECK(!opt_.project_residual || opt_.residual_spectral_wiener, "project_residual needs the spectral Wiener base");
  TORCH_CHECK(!opt_.fuse_defocus_reader || (opt_.residual_spectral_wiener && K > 0),
              "fuse_defocus_reader needs the spectral Wiener base and layer_depths_m");
  TORCH_CHECK(!(opt_.residual_preinverse && opt_.residual_spectral_wiener),
              "the residual's base is the pre-inversion or the spectral Wiener cube, not both");
  TORCH_CHECK(upsampling_weights.dim() == 2 && upsampling_weights.size(0) == opt_.bands &&
                  upsampling_weights.size(1) == opt_.in_channels,
              "upsampling weights must be [bands, in_channels]");
  std::vector<int64_t> width;
  for (int64_t l = 0; l <= opt_.levels; ++l) width.push_back(opt_.base_width << l);
  for (int64_t l = 0; l < opt_.levels; ++l)
    down_.push_back(register_module(
        "down" + std::to_string(l),
        block(l == 0 ? opt_.in_channels * (1 + opt_.preinverse_layers) + (opt_.base_as_input ? opt_.bands : 0) +
                         (opt_.defocus_cost != DefocusCost::none ? K : 0)
                     : width[size_t(l - 1)],
              width[size_t(l)])));
  bottom_ = register_module("bottom", block(width[size_t(opt_.levels - 1)], width[size_t(opt_.levels)]));
  for (int64_t l = opt_.levels - 1; l >= 0; --l) {
    const std::string s = std::to_string(l);
    const int64_t w = width[size_t(l)], below = width[size_t(l + 1)];
    up_hs_.push_back(register_module("up_hs" + s, torch::nn::Conv2d(torch::nn::Conv2dOptions(below, w, 3).padding(1))));
    dec_hs_.push_back(register_module("dec_hs" + s, block(2 * w, w)));
    up_depth_.push_back(register_module("up_depth" + s, torch::nn::Conv2d(torch::nn::Conv2dOptions(below, w, 3).padding(1))));
    dec_depth_.push_back(register_module("dec_depth" + s, block(2 * w, w)));
  }
  head_hs_ = register_module("head_hs", torch::nn::Conv2d(torch::nn::Conv2dOptions(width[0], opt_.bands, 1)));
  TORCH_CHECK(opt_.depth_bins == 0 || opt_.depth_bins >= 2, "depth_bins must be 0 (a sigmoid) or >= 2");
  head_depth_ = register_module(
      "head_depth", torch::nn::Conv2d(torch::nn::Conv2dOptions(width[0], std::max<int64_t>(1, opt_.depth_bins), 1)));
  TORCH_CHECK(opt_.refine_width >= 0, "refine_width must be >= 0");
  if (opt_.refine_width > 0) {
    CubeRefinerOptions r;
    r.in_channels = opt_.in_channels, r.bands = opt_.bands, r.base_width = opt_.refine_width, r.levels = opt_.levels;
    r.norm = opt_.norm;
    refiner_ = register_module("refiner", CubeRefiner(r));
  }
  const torch::Tensor w0 = upsampling_weights.to(torch::kFloat32).clone();
  weights_ = opt_.learned_spectral_map ? register_parameter("upsampling_weights", w0)
                                       : register_buffer("upsampling_weights", w0);
  if (opt_.residual_spectral_wiener) {  // zeros until set_spectral_prior (or a checkpoint) fills them
    sw_mean_ = register_buffer("sw_mean", torch::zeros({opt_.bands}));
    sw_cov_ = register_buffer("sw_covariance", torch::zeros({opt_.bands, opt_.bands}));
    sw_noise_var_ = register_buffer("sw_noise_var", torch::zeros({1}));
    sw_omega_ = register_buffer("sw_omega", torch::zeros({opt_.in_channels, opt_.bands}));
  }
}

void HsdNetImpl::set_spectral_prior(const torch::Tensor& mean, const torch::Tensor& covariance, double noise_var,
                                    const torch::Tensor& omega) {
  TORCH_CHECK(opt_.residual_spectral_wiener, "HsdNet: set_spectral_prior without residual_spectral_wiener");
  TORCH_CHECK(mean.numel() == opt_.bands && covariance.sizes() == sw_cov_.sizes() && omega.sizes() == sw_omega_.sizes() &&
                  noise_var > 0,
              "spectral prior must be mean [", opt_.bands, "], covariance [", opt_.bands, ", ", opt_.bands,
              "], omega [3, ", opt_.bands, "] and a noise variance > 0");
  torch::NoGradGuard no_grad;
  sw_mean_.copy_(mean.reshape({-1}));
  sw_cov_.copy_(covariance);
  sw_noise_var_.fill_(noise_var);
  sw_omega_.copy_(omega);
}

void HsdNetImpl::set_band_psf(const torch::Tensor& psf) {
  TORCH_CHECK(psf.dim() == 4 && psf.size(0) == opt_.bands, "band PSFs must be [", opt_.bands, ", K, P, P], got ",
              psf.sizes());
  band_psf_ = psf;
}

void HsdNetImpl::set_illuminant_moments(const IlluminantMoments& m) {
  TORCH_CHECK(m.mean.defined() && m.mean.dim() == 2 && m.mean.size(1) == opt_.bands,
              "illuminant moments must be [K, ", opt_.bands, "]");
  illum_ = m;
}

torch::Tensor HsdNetImpl::illuminant_posterior(const torch::Tensor& image) const {
  TORCH_CHECK(illum_.mean.defined(), "HsdNet: the illuminant reader needs set_illuminant_moments first");
  TORCH_CHECK(band_psf_.defined(), "HsdNet: the illuminant reader needs set_band_psf first");
  torch::NoGradGuard no_grad;
  const torch::Tensor energy = band_psf_.detach().to(torch::kFloat64).sum({2, 3}).mean(1);  // [L]
  const torch::Tensor ll = illuminant_log_likelihood(image, sw_omega_, energy, illum_, sw_noise_var_.item<double>(),
                                                     opt_.illuminant_reader.block_px);
  return model::illuminant_posterior(ll, image.size(2), image.size(3), opt_.illuminant_reader);
}

SpectralPrior HsdNetImpl::prior_for(const torch::Tensor& image) const {
  const SpectralPrior buffers{sw_mean_, sw_cov_, sw_noise_var_.item<double>()};
  if (!opt_.read_illuminant || is_training()) return buffers;
  TORCH_CHECK(image.size(0) == 1, "HsdNet::prior_for takes one image");
  const torch::Tensor w = illuminant_posterior(image)[0];
  return illuminant_mixture_prior(illum_, w, buffers.noise_var);
}

torch::Tensor HsdNetImpl::spectral_wiener(const torch::Tensor& image) const {
  TORCH_CHECK(opt_.residual_spectral_wiener, "HsdNet: spectral_wiener without residual_spectral_wiener");
  TORCH_CHECK(band_psf_.defined(), "HsdNet: the spectral Wiener base needs set_band_psf first");
  TORCH_CHECK(sw_noise_var_.item<double>() > 0, "HsdNet: the spectral Wiener base's prior was never set");
  const SpectralPrior prior{sw_mean_, sw_cov_, sw_noise_var_.item<double>()};
  check_spectral_inputs("HsdNet::spectral_wiener", image, band_psf_, sw_omega_, prior);
  const int64_t H = image.size(2), W = image.size(3);
  WienerKeep& k = sw_keep_;
  // A PSF stack in an autograd graph is this step's: its filter must be in the graph too.
  const bool keepable = !(torch::GradMode::is_enabled() && band_psf_.requires_grad());
  if (keepable && !(k.psf.matches(band_psf_) && k.H == H && k.W == W)) {  // new PSFs or size: all kept is stale
    k = WienerKeep();
    k.psf = TensorSnapshot(band_psf_), k.H = H, k.W = W;
  }
  const bool edges = opt_.edge_prior.weight > 0 && !is_training();
  if ((opt_.read_illuminant || edges) && !is_training()) {  // one prior per image; the edge prior's iterations
    const SpectralOtf otf = keepable ? kept_otf(H, W) : spectral_otf(band_psf_, H, W);
    std::vector<torch::Tensor> out;
    for (int64_t b = 0; b < image.size(0); ++b) {
      const torch::Tensor x = image.narrow(0, b, 1);
      const SpectralPrior p = prior_for(x);
      out.push_back((edges ? spectral_tv_cube(x, otf, sw_omega_, p, opt_.edge_prior)
                           : apply_spectral_wiener(spectral_wiener_filter(otf, sw_omega_, p), x))
                        .to(torch::kFloat32));
    }
    return torch::cat(out, 0);
  }
  const bool same_prior = holds_prior(k, sw_mean_, sw_cov_, sw_noise_var_, sw_omega_);
  if (keepable && same_prior && k.filter) return apply_spectral_wiener(*k.filter, image).to(torch::kFloat32);
  SpectralWienerFilter f = spectral_wiener_filter(spectral_otf(band_psf_, H, W), sw_omega_, prior);
  const torch::Tensor cube = apply_spectral_wiener(f, image).to(torch::kFloat32);
  if (keepable && same_prior) {  // the second use of these inputs: keep the filter
    k.filter = std::make_shared<SpectralWienerFilter>(std::move(f));
  } else if (keepable) {  // the first use of this prior: remember it, keep the filter on the next
    remember_prior(k, sw_mean_, sw_cov_, sw_noise_var_, sw_omega_);
    k.filter.reset();
  }
  return cube;
}

SpectralWienerFilter HsdNetImpl::projection_filter(int64_t H, int64_t W) const {
  TORCH_CHECK(band_psf_.defined(), "HsdNet: project_residual needs set_band_psf first");
  TORCH_CHECK(sw_noise_var_.item<double>() > 0, "HsdNet: project_residual's prior was never set");
  const SpectralPrior prior{sw_mean_, sw_cov_, sw_noise_var_.item<double>()};
  WienerKeep& k = proj_keep_;
  const bool keepable = !(torch::GradMode::is_enabled() && band_psf_.requires_grad());
  if (keepable && k.filter && k.H == H && k.W == W && k.psf.matches(band_psf_) &&
      holds_prior(k, sw_mean_, sw_cov_, sw_noise_var_, sw_omega_))
    return *k.filter;
  SpectralWienerFilter f = spectral_wiener_filter(spectral_otf(band_psf_, H, W), sw_omega_, prior);
  if (keepable) {
    k = WienerKeep();
    k.psf = TensorSnapshot(band_psf_), k.H = H, k.W = W;
    remember_prior(k, sw_mean_, sw_cov_, sw_noise_var_, sw_omega_);
    k.filter = std::make_shared<SpectralWienerFilter>(f);
  }
  return f;
}

SpectralOtf HsdNetImpl::kept_otf(int64_t H, int64_t W) const {
  WienerKeep& k = sw_keep_;
  if (k.otf) return *k.otf;
  SpectralOtf o = spectral_otf(band_psf_, H, W);
  if (o.Kf.numel() * int64_t(o.Kf.element_size()) <= kMaxKeptOtfBytes) k.otf = std::make_shared<SpectralOtf>(o);
  return o;
}

void HsdNetImpl::set_replica_group(const std::shared_ptr<ReplicaGroup>& group) {
  for (const auto& m : modules())
    if (auto* bn = m->as<SyncBatchNorm2dImpl>()) bn->set_replica_group(group);
}

void HsdNetImpl::set_preinverse_psf(const torch::Tensor& rgb_psf) {
  TORCH_CHECK(rgb_psf.dim() == 4 && rgb_psf.size(0) == opt_.preinverse_layers && rgb_psf.size(1) == opt_.in_channels,
              "pre-inversion PSFs must be [", opt_.preinverse_layers, ", ", opt_.in_channels, ", P, P], got ",
              rgb_psf.sizes());
  preinverse_psf_ = rgb_psf;
}

torch::Tensor HsdNetImpl::preinverse(const torch::Tensor& image) const {
  TORCH_CHECK(preinverse_psf_.defined(), "HsdNet: the pre-inversion is on but set_preinverse_psf was not called");
  return wiener_preinverse(image, preinverse_psf_, opt_.preinverse_reg).to(image.scalar_type());
}

torch::Tensor HsdNetImpl::defocus_input(const torch::Tensor& image) const {
  // With defocus_cost_gradient the spectral costs are differentiable in the
  // image (never in the PSFs): the depth term reaches the DOE through them as
  // through the image. Otherwise no gradient passes.
  const bool graded = opt_.defocus_cost == DefocusCost::spectral && opt_.defocus_cost_gradient;
  std::optional<torch::NoGradGuard> no_grad;
  if (!graded) no_grad.emplace();
  torch::Tensor cost;
  if (opt_.defocus_cost == DefocusCost::grey) {
    TORCH_CHECK(preinverse_psf_.defined(), "HsdNet: the grey cost volume needs set_preinverse_psf first");
    cost = defocus_cost_volume(image.detach(), preinverse_psf_.detach(), DefocusModel());
  } else {
    cost = spectral_reader_cost(graded ? image : image.detach(), kDefocusInputWindowPx);
  }
  return (cost - cost.mean(1, true)).to(image.scalar_type());
}

torch::Tensor HsdNetImpl::spectral_reader_cost(const torch::Tensor& image, int64_t window_px) const {
  TORCH_CHECK(band_psf_.defined() && sw_noise_var_.item<double>() > 0,
              "HsdNet: the spectral depth-from-defocus reader needs set_band_psf and set_spectral_prior first");
  TORCH_CHECK(band_psf_.size(1) == int64_t(opt_.layer_depths_m.size()), "HsdNet: the band PSFs have ", band_psf_.size(1),
              " depths, the network ", opt_.layer_depths_m.size());
  // The buffers' prior even with read_illuminant: the light read made the
  // fused depth worse on the quick config's test split, the light known too
  // (docs/learning.md, "Reading the light").
  const SpectralPrior prior{sw_mean_, sw_cov_, sw_noise_var_.item<double>()};
  return spectral_defocus_cost_volume(image, band_psf_, sw_omega_, prior, window_px);  // the PSFs enter as constants
}

torch::Tensor HsdNetImpl::fusion_reader_cost(const torch::Tensor& image) const {
  torch::NoGradGuard no_grad;
  const torch::Tensor c = spectral_reader_cost(image.detach(), opt_.fusion.reader_box_px).to(torch::kFloat32);
  return c - c.mean(1, true);
}

torch::Tensor HsdNetImpl::reader_depth(const torch::Tensor& image, const torch::Tensor& guide, const torch::Tensor& cost) const {
  torch::NoGradGuard no_grad;
  const torch::Tensor c = cost.defined() ? cost.to(torch::kFloat32) : fusion_reader_cost(image);
  return filtered_reader_depth(c, guide.detach().to(torch::kFloat32), opt_.layer_depths_m, opt_.fusion);
}

NetOutput HsdNetImpl::forward(const torch::Tensor& image, const torch::Tensor& preinverse_in, const torch::Tensor& base_in,
                              const torch::Tensor& reader_cost_in) {
  TORCH_CHECK(image.dim() == 4 && image.size(1) == opt_.in_channels, "network input must be [B, ", opt_.in_channels,
              ", H, W], got ", image.sizes());
  const int64_t H = image.size(2), W = image.size(3), m = int64_t(1) << opt_.levels;
  const int64_t ph = (m - H % m) % m, pw = (m - W % m) % m;
  torch::Tensor x = image;
  torch::Tensor base = image;  // what the cube's residual is added to, after spectral upsampling
  if (opt_.preinverse_layers > 0) {
    const torch::Tensor p = preinverse_in.defined() ? preinverse_in : preinverse(image);
    TORCH_CHECK(p.dim() == 4 && p.size(0) == image.size(0) && p.size(1) == opt_.in_channels * opt_.preinverse_layers &&
                    p.size(2) == H && p.size(3) == W,
                "pre-inversion input must be [B, ", opt_.in_channels * opt_.preinverse_layers, ", H, W], got ", p.sizes());
    x = torch::cat({image, p}, 1);
    if (opt_.defocus_cost == DefocusCost::grey) x = torch::cat({x, defocus_input(image)}, 1);
    if (opt_.residual_preinverse)
      base = preinverse_layer_mean(p, opt_.preinverse_layers).to(image.scalar_type());
  }
  // The cube the head's residual is added to [B, L, H, W] (float32).
  torch::Tensor cube_base;
  if (opt_.residual_spectral_wiener) {
    cube_base = base_in.defined() ? base_in : spectral_wiener(image);
    TORCH_CHECK(cube_base.dim() == 4 && cube_base.size(0) == image.size(0) && cube_base.size(1) == opt_.bands &&
                    cube_base.size(2) == H && cube_base.size(3) == W,
                "residual base must be [B, ", opt_.bands, ", H, W], got ", cube_base.sizes());
  } else {
    cube_base = spectral_upsample(weights_, base);
  }
  if (opt_.base_as_input) x = torch::cat({x, cube_base.to(x.scalar_type())}, 1);
  if (opt_.defocus_cost == DefocusCost::spectral) x = torch::cat({x, defocus_input(image)}, 1);
  if (ph || pw) {  // reflect needs pad < size; replicate always works
    F::PadFuncOptions o({0, pw, 0, ph});
    if (ph < H && pw < W) o.mode(torch::kReflect);
    else o.mode(torch::kReplicate);
    x = F::pad(x, o);
  }
  // Mixed precision in training (see unet.h); padding first (no bfloat16 padding kernels on the CPU).
  const bool mixed = is_training() && opt_.train_dtype != torch::kFloat32;
  if (mixed) x = x.to(opt_.train_dtype).contiguous(torch::MemoryFormat::ChannelsLast);
  std::vector<torch::Tensor> skips;
  for (auto& d : down_) {
    x = run_block(d, x);
    skips.push_back(x);
    x = F::max_pool2d(x, F::MaxPool2dFuncOptions(2));
  }
  const torch::Tensor bottom = run_block(bottom_, x);
  auto decode = [&](std::vector<torch::nn::Conv2d>& up, std::vector<torch::nn::Sequential>& dec) {
    torch::Tensor y = bottom;
    for (size_t k = 0; k < up.size(); ++k) {
      const torch::Tensor& skip = skips[skips.size() - 1 - k];
      y = F::interpolate(y, F::InterpolateFuncOptions()
                                .size(std::vector<int64_t>{skip.size(2), skip.size(3)})
                                .mode(torch::kBilinear)
                                .align_corners(false));
      y = torch::relu(run_conv(up[k], y));
      y = run_block(dec[k], torch::cat({y, skip}, 1));
    }
    return y;
  };
  torch::Tensor hs = run_conv(head_hs_, decode(up_hs_, dec_hs_)).to(torch::kFloat32).contiguous();
  torch::Tensor d = run_conv(head_depth_, decode(up_depth_, dec_depth_)).to(torch::kFloat32).contiguous();
  if (ph || pw) {
    hs = hs.narrow(2, 0, H).narrow(3, 0, W);
    d = d.narrow(2, 0, H).narrow(3, 0, W);
  }
  NetOutput out;
  if (opt_.depth_bins >= 2) {  // the soft argmax over the bins' centres t_k = k/(N-1)
    out.depth_logits = d;
    const torch::Tensor t = torch::linspace(0.0, 1.0, opt_.depth_bins, d.options()).view({1, -1, 1, 1});
    d = (torch::softmax(d, 1) * t).sum(1, /*keepdim=*/true);
  } else {
    d = torch::sigmoid(d);
  }
  // One projection filter for both stages (made once per step while the PSFs carry a gradient).
  std::optional<SpectralWienerFilter> projection;
  if (opt_.project_residual) projection = projection_filter(H, W);
  if (projection) hs = spectral_wiener_unobserved(*projection, hs);
  out.hs = hs + cube_base;
  if (refiner_) {  // the second stage: x₂ = x₁ + R([y, x₁]), R through (I − W H̄) too with project_residual
    out.first_stage_hs = out.hs;
    torch::Tensor r = refiner_->forward(image, out.hs);
    if (projection) r = spectral_wiener_unobserved(*projection, r);
    out.hs = out.hs + r;
  }
  const double inv_far = 1.0 / opt_.depth_max_m, inv_near = 1.0 / opt_.depth_min_m;
  out.inv_depth = inv_far + d * (inv_near - inv_far);
  out.depth_m = 1.0 / out.inv_depth;
  out.depth_unit = d;
  if (opt_.fuse_defocus_reader && !is_training()) {
    const torch::Tensor guide = fusion_guide(out.hs.detach());
    TORCH_CHECK(!reader_cost_in.defined() ||
                    (reader_cost_in.dim() == 4 && reader_cost_in.size(0) == image.size(0) &&
                     reader_cost_in.size(1) == int64_t(opt_.layer_depths_m.size()) && reader_cost_in.size(2) == H &&
                     reader_cost_in.size(3) == W),
                "reader cost must be [B, ", opt_.layer_depths_m.size(), ", H, W], got ", reader_cost_in.sizes());
    const torch::Tensor reader = reader_depth(image, guide, reader_cost_in);
    out.network_depth_m = out.depth_m;
    out.reader_depth_m = reader;
    out.depth_m = fuse_depths(out.depth_m, reader, guide, opt_.depth_min_m, opt_.depth_max_m, opt_.fusion);
    out.inv_depth = 1.0 / out.depth_m;
  }
  return out;
}

void HsdNetImpl::start_at_baselines(double inv_depth_per_m) {
  torch::NoGradGuard no_grad;
  head_hs_->weight.zero_();
  head_hs_->bias.zero_();
  head_depth_->weight.zero_();
  if (refiner_) refiner_->start_at_zero();
  const double inv_far = 1.0 / opt_.depth_max_m, inv_near = 1.0 / opt_.depth_min_m;
  const double u = std::clamp((inv_depth_per_m - inv_far) / (inv_near - inv_far), 1e-3, 1.0 - 1e-3);
  if (opt_.depth_bins >= 2) {
    // Gaussian logits −(t_k − μ)²/(2σ²), σ two bins wide, with μ found by
    // bisection so that the soft argmax Σ p_k t_k is u (it rises monotonically
    // with μ). Not a one- or two-hot start: bins at probability ~0 would get no
    // gradient from the depth term.
    const int64_t N = opt_.depth_bins;
    const torch::Tensor t = torch::linspace(0.0, 1.0, N, torch::kFloat64);
    const double sigma = 2.0 / double(N - 1);
    auto logits = [&](double mu) { return -(t - mu).pow(2) / (2.0 * sigma * sigma); };
    auto mean = [&](double mu) { return (torch::softmax(logits(mu), 0) * t).sum().item<double>(); };
    double lo = -1.0, hi = 2.0;  // mean(lo) < 1e-3 <= u <= 1 - 1e-3 < mean(hi)
    for (int i = 0; i < 100; ++i) {
      const double mid = 0.5 * (lo + hi);
      (mean(mid) < u ? lo : hi) = mid;
    }
    head_depth_->bias.copy_(logits(0.5 * (lo + hi)).to(head_depth_->bias.dtype()));
  } else {
    head_depth_->bias.fill_(std::log(u / (1.0 - u)));
  }
}

}  // namespace hsd::model
