#include "train/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <optional>
#include <sstream>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/tensor_io.h"
#include "common/text_format.h"
#include "data/manifest.h"
#include "data/synthetic_dataset.h"
#include "model/net_options.h"
#include "model/spectral_upsampling.h"
#include "model/spectral_wiener.h"
#include "model/wiener_preinverse.h"
#include "optics/fabrication_error.h"
#include "optics/psf_source.h"
#include "train/baselines.h"
#include "train/checkpoint.h"
#include "train/gradient_scale.h"
#include "train/metrics_log.h"
#include "train/schedule.h"
#include "train/shared_psf.h"
#include "train/step_profiler.h"
#include "train/validation_pictures.h"

namespace hsd::train {

namespace {

uint64_t mix(uint64_t a, uint64_t b) {
  uint64_t x = a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E019ull + (a << 6) + (a >> 2));
  x ^= x >> 31;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 29;
  return x;
}

// train.fabrication_noise: the height map the optics see in training step
// `step`, the DOE perturbed by one random draw of fabrication errors (the same
// on every rank: seeded by the run's seed and the step). The gradient flows
// through the errors (blur, scale and shift are linear in the map, roughness
// adds to it), so the DOE follows the gradient of the loss averaged over the
// errors; a straight-through gradient (identity) made the DOE finer and more
// fragile under edge rounding (docs/fabrication.md). With
// train.fabrication_noise_ramp_steps the scales grow linearly to their full
// size at that step (a curriculum).
torch::Tensor with_fabrication_noise(const torch::Tensor& h, const Config& cfg, const optics::Doe& doe, int64_t step) {
  const int64_t ramp = cfg.train.fabrication_noise_ramp_steps;
  const FabricationErrorConfig scales = ramp > 0 ? optics::scaled_fabrication_error(
                                                       cfg.train.fabrication_noise, std::min(1.0, double(step) / double(ramp)))
                                                 : cfg.train.fabrication_noise;
  if (optics::no_fabrication_error(scales)) return h;
  std::mt19937_64 rng(mix(cfg.seed ^ 0xFAB0FAB0ull, uint64_t(step)));
  double angle = 0;
  const FabricationErrorConfig e = optics::draw_fabrication_error(scales, rng, &angle);
  return optics::fabricated_surface(h, e, {doe.pitch_m(), 1, doe.max_height_m(), 0, angle}, rng());
}
constexpr uint64_t kValSeed = 0x5EEDULL;


Batch stack(const std::vector<data::Patch>& patches, torch::Device device) {
  std::vector<torch::Tensor> r, d;
  for (const auto& p : patches) r.push_back(p.spectral), d.push_back(p.depth_m);
  return {torch::stack(r).to(device), torch::stack(d).to(device)};
}

// One noise generator per image, keyed by its index in the global batch: a
// rank's slice gets the noise it would get in one process's whole batch.
std::vector<at::Generator> image_generators(uint64_t key, int64_t first, int64_t count) {
  std::vector<at::Generator> g;
  for (int64_t i = 0; i < count; ++i) g.push_back(at::detail::createCPUGenerator(mix(key, uint64_t(first + i))));
  return g;
}

void check_grads(const std::vector<std::pair<std::string, torch::Tensor>>& params, int64_t step) {
  // One read-out for all (a device sync each would cost ~70 per step); the
  // tensor-by-tensor search only when something is not finite.
  std::vector<torch::Tensor> ok;
  for (const auto& np : params)
    if (np.second.grad().defined()) ok.push_back(torch::isfinite(np.second.grad()).all());
  if (ok.empty() || torch::stack(ok).all().item<bool>()) return;
  for (const auto& [name, p] : params)
    if (p.grad().defined() && !torch::isfinite(p.grad()).all().item<bool>())
      throw NumericalError("step " + std::to_string(step) + ": the gradient of " + name +
                           " holds NaN or Inf (lower train.lr_net/lr_doe_m or check the data)");
}

}  // namespace

int64_t render_margin_px(const Config& cfg) {
  return cfg.data.render_margin_px >= 0 ? cfg.data.render_margin_px
                                        : cfg.optics.psf_size / 2 + int64_t(std::ceil(3.0 * cfg.sensor.mask_sigma_px));
}

optics::PsfSpec training_psf_spec(const Config& cfg, const optics::Material& material, torch::Device device) {
  optics::PsfSpec spec = optics::make_psf_spec(cfg.optics, material, device);
  spec.depth_basis = true;  // the kernels are reused every step: factor them once over all depths (psf.h)
  return spec;
}

Trainer::Trainer(const Config& cfg, std::shared_ptr<DataParallel> group)
    : cfg_(cfg),
      ranks_(group && group->world_size() > 1 ? std::shared_ptr<Collectives>(std::move(group))
                                              : std::make_shared<SingleProcess>()),
      rank_(ranks_->rank()),
      world_(ranks_->world_size()),
      device_(resolve_device(cfg.device)),
      material_(optics::Material::load(cfg.optics.material)),
      psf_(std::make_unique<optics::PsfSimulator>(training_psf_spec(cfg, material_, device_))),
      sensor_(optics::make_sensor_model(cfg.sensor, psf_->spec(), cfg.optics.band_width_m())),
      doe_(optics::make_doe(cfg.optics, material_, cfg.seed, device_)) {
  {
    // The network's initial weights come from torch's global generator: seeded
    // and drawn under one lock, so trainers built on several threads at once
    // (ranks as threads in tests) each get the seed's weights.
    static std::mutex global_rng;
    std::lock_guard<std::mutex> lock(global_rng);
    torch::manual_seed(int64_t(cfg.seed));
    const torch::Tensor w = model::spectral_upsampling_weights(sensor_.omega.cpu());
    model::NetOptions o = model::net_options(cfg);
    precision_ = training_precision(cfg.train.precision, device_);
    o.train_dtype = precision_.dtype;
    net_ = model::HsdNet(o, w);
    upsampling_w_ = w.to(torch::kFloat32);
  }
  if (cfg.optics.field_angle_deg != 0.0)
    input_error("config key optics.field_angle_deg", "is for hsd_psf's off-axis analysis; training and evaluation image with the "
                                                     "shift-invariant on-axis model (set it to 0)");
  fixed_psf_ = optics::psf_source_provider(cfg.optics, material_, device_);
  if (fixed_psf_) {
    const std::string file = optics::psf_file_path(cfg.optics);
    if (!file.empty())
      log::info("optics.psf_source: imaging through the PSF stack " + file + "; the DOE is not used and only the network is trained");
    else if (!cfg.train.freeze_doe)
      log::info("optics.psf_source = \"all_in_focus\": the control; the DOE is not used and only the network is trained");
  }
  doe_trained_ = !cfg.train.freeze_doe && !fixed_psf_;
  psf_still_ = fixed_psf_ || (!doe_trained_ && optics::no_fabrication_error(cfg.train.fabrication_noise));
  // The PSF's reach plus the soft layer masks' (3σ): then the patch's image is
  // the whole scene's image at those pixels (tests: sensor, margin).
  margin_ = render_margin_px(cfg);
  if (cfg.train.network_context_px > margin_)
    throw InputError("train.network_context_px: " + std::to_string(cfg.train.network_context_px) +
                     " px is more scene than is rendered around a patch (data.render_margin_px: " + std::to_string(margin_) +
                     " px)");
  net_->to(device_);
  refresh_preinverse();
  weights_ = {cfg.train.loss_alpha, cfg.train.loss_beta, cfg.train.loss_gamma, cfg.train.depth_loss};
  weights_.ce = cfg.train.depth_ce_weight;
  weights_.hs_loss = cfg.train.hs_loss;
  weights_.inv_far = 1.0 / net_->options().depth_max_m, weights_.inv_near = 1.0 / net_->options().depth_min_m;
  std::vector<torch::optim::OptimizerParamGroup> groups;
  groups.emplace_back(net_->parameters(), std::make_unique<torch::optim::AdamOptions>(cfg.train.lr_net));
  if (!doe_trained_) {
    doe_.parameter().set_requires_grad(false);
  } else {
    groups.emplace_back(std::vector<torch::Tensor>{doe_.parameter()},
                        std::make_unique<torch::optim::AdamOptions>(
                            torch::optim::AdamOptions(cfg.train.lr_doe_m).betas({cfg.train.doe_adam_beta1, 0.999})));
  }
  opt_ = std::make_unique<torch::optim::Adam>(std::move(groups), torch::optim::AdamOptions(cfg.train.lr_net));
  check_global_batch(cfg, world_);
  // Batch norm over the global batch and PSFs shared out: only among several ranks.
  if (world_ > 1 && cfg.distributed.sync_batch_norm) net_->set_replica_group(ranks_);
  if (world_ > 1 && cfg.distributed.split_psf && !fixed_psf_) shared_psf_ = make_shared_psf_provider(*psf_, ranks_);
  ranks_->broadcast_(replicated_state(), "the initial network and DOE");
}

void check_global_batch(const Config& cfg, int world_size) {
  if (cfg.train.batch_size % world_size != 0)
    input_error("config key train.batch_size", std::to_string(cfg.train.batch_size) + " does not split evenly over " +
                                                   std::to_string(world_size) + " ranks (WORLD_SIZE)");
}

std::vector<torch::Tensor> Trainer::trained_parameters() const {
  std::vector<torch::Tensor> p = net_->parameters();
  if (doe_trained_) p.push_back(doe_.parameter());
  return p;
}

std::vector<std::string> Trainer::trained_names() const {
  std::vector<std::string> n;
  for (const auto& p : net_->named_parameters()) n.push_back("net." + p.key());
  if (doe_trained_) n.push_back("doe.raw");
  return n;
}

void Trainer::reset_average() {
  average_.clear();
  average_in_use_ = false;
  if (cfg_.train.ema_decay <= 0.0) return;
  torch::NoGradGuard no_grad;
  for (const auto& p : trained_parameters()) average_.push_back(p.detach().clone());
}

void Trainer::swap_average() {
  torch::NoGradGuard no_grad;
  const std::vector<torch::Tensor> params = trained_parameters();
  for (size_t i = 0; i < params.size(); ++i) {
    const torch::Tensor kept = params[i].detach().clone();
    params[i].copy_(average_[i]);
    average_[i].copy_(kept);
  }
  average_in_use_ = !average_in_use_;
}

void Trainer::hold_in_parameters(bool average) {
  if (cfg_.train.ema_decay <= 0.0) return;
  if (average_.empty()) reset_average();
  if (average_in_use_ != average) swap_average();
}

void Trainer::update_average(int64_t step) {
  if (cfg_.train.ema_decay <= 0.0) return;
  // The decay ramps up from 0.1 (Tensorflow's num_updates rule), so early
  // steps, far from where training ends, leave the average soon.
  const double d = std::min(cfg_.train.ema_decay, (1.0 + double(step)) / (10.0 + double(step)));
  torch::NoGradGuard no_grad;
  const std::vector<torch::Tensor> params = trained_parameters();
  for (size_t i = 0; i < params.size(); ++i) average_[i].lerp_(params[i].detach(), 1.0 - d);
}

std::vector<torch::Tensor> Trainer::replicated_state(bool with_buffers) const {
  std::vector<torch::Tensor> t = net_->parameters();
  if (with_buffers)
    for (const auto& b : net_->buffers()) t.push_back(b);
  t.push_back(doe_.parameter());
  for (const auto& g : opt_->param_groups())
    for (const auto& p : g.params()) {
      const auto it = opt_->state().find(c10::guts::to_string(p.unsafeGetTensorImpl()));
      if (it == opt_->state().end()) continue;
      const auto& st = static_cast<const torch::optim::AdamParamState&>(*it->second);
      t.push_back(st.exp_avg());
      t.push_back(st.exp_avg_sq());
    }
  for (const auto& a : average_) t.push_back(a);
  return t;
}

void Trainer::check_replicas_agree(int64_t step) {
  if (world_ == 1) return;  // nothing to compare
  torch::NoGradGuard no_grad;
  // Batch norm per rank (distributed.sync_batch_norm = false): the running
  // statistics differ by design (validate() takes rank 0's), so only the rest is compared.
  const std::vector<torch::Tensor> state = replicated_state(cfg_.distributed.sync_batch_norm);
  std::vector<torch::Tensor> rank0;
  for (const auto& t : state) rank0.push_back(t.detach().clone());
  ranks_->broadcast_(rank0, "rank 0's parameters (agreement check)");
  double diff = 0.0;
  for (size_t i = 0; i < state.size(); ++i)
    if (state[i].numel() > 0)
      diff = std::max(diff, (state[i].to(torch::kFloat64) - rank0[i].to(torch::kFloat64)).abs().max().item<double>());
  const std::vector<double> slots = ranks_->gather(diff, "parameter differences");
  bool drifted = false;
  for (int64_t r = 1; r < world_; ++r)
    if (slots[size_t(r)] != 0.0) {
      drifted = true;
      if (rank_ == 0)
        log::warn("step " + std::to_string(step) + ": rank " + std::to_string(r) + "'s parameters differ from rank 0's by up to " +
                c10::str(slots[size_t(r)]) + " (rounding on unlike hosts?); every rank takes rank 0's");
    }
  if (drifted)
    for (size_t i = 0; i < state.size(); ++i) state[i].detach().copy_(rank0[i]);
}

void Trainer::attach_data() {
  // Rank 0 makes the dataset if needed while the others wait (as long as it
  // shows a heartbeat). The others never generate one: their data.root must
  // hold rank 0's dataset (a shared folder, or a copy on each host).
  std::string root;
  ranks_->run_on_rank0("dataset", [&] { root = data::ensure_dataset(cfg_); }, "to provide the dataset " + cfg_.data.root);
  if (rank_ != 0) {
    Config local = cfg_;
    local.data.generate_if_missing = false;
    root = data::ensure_dataset(local);
  }
  const auto bands = cfg_.optics.wavelengths_m();
  const double bw = cfg_.optics.band_width_m();
  train_scenes_ = data::load_split(root, "train", bands, bw, cfg_.data.loader_threads);
  baseline_inv_depth_ = median_inverse_depth(train_scenes_);
  // A checkpoint, if resumed, replaces the heads; train.init_checkpoint's are kept.
  if (cfg_.model.head_init == HeadInit::baselines && !network_started_) net_->start_at_baselines(baseline_inv_depth_);
  reset_average();  // from the weights training starts with (a resumed run then reads its own)
  const data::Manifest m = data::read_manifest(root);
  bank_ = std::make_unique<data::IlluminantBank>(cfg_.data.illuminants, bands, bw);
  if (net_->options().residual_spectral_wiener) {  // the prior: the training radiance's moments, the sensor's noise
    const model::SpectralPrior p = training_spectral_prior(train_scenes_, cfg_, sensor_);
    net_->set_spectral_prior(p.mean, p.covariance, p.noise_var, sensor_.omega.to(torch::kFloat32));
    give_illuminant_moments(train_scenes_);  // used with model.read_illuminant; kept in checkpoints either way
  }
  const int64_t rendered = cfg_.data.patch_size_px + 2 * margin_;
  const int64_t overhang = cfg_.data.border_patches ? margin_ : 0;  // the patch's centre anywhere in the scene
  sampler_ = std::make_unique<data::PatchSampler>(train_scenes_, rendered, 8, 4, overhang);
  // Validation: the val split (the train split with other patches if there is none).
  std::unique_ptr<data::PatchSampler> val_sampler;
  if (!m.split("val").empty()) {
    val_scenes_ = data::load_split(root, "val", bands, bw, cfg_.data.loader_threads);
    val_sampler = std::make_unique<data::PatchSampler>(val_scenes_, rendered, 8, 4, overhang);
  } else {
    log::warn(root + "/manifest.json has no val split: validating on other patches of the train split");
  }
  const data::PatchSampler& vs = val_sampler ? *val_sampler : *sampler_;
  std::vector<data::Patch> patches;
  for (const auto& s : vs.draw(cfg_.train.val_patches, mix(cfg_.seed, kValSeed), bank_->size(), cfg_.data.intensity_min,
                               cfg_.data.intensity_max))
    patches.push_back(vs.extract(s, bank_.get()));
  val_ = stack(patches, device_);
  log::info("data: " + std::to_string(train_scenes_.size()) + " train scenes (" + std::to_string(sampler_->candidates()) +
            " valid windows), " + std::to_string(patches.size()) + " validation patches of " +
            std::to_string(cfg_.data.patch_size_px) + " px (rendered with " + std::to_string(margin_) +
            " px of scene around them); constant-depth baseline " +
            format("%.3f m", 1.0 / baseline_inv_depth_) + " (the train split's median inverse depth)");
}

namespace {
// The centre S×S of [B, C, S', S'] (itself when S' <= S; undefined stays undefined).
torch::Tensor centre_square(const torch::Tensor& t, int64_t S) {
  if (!t.defined()) return t;
  const int64_t m = (t.size(2) - S) / 2;
  if (m <= 0) return t;
  return t.narrow(2, m, S).narrow(3, m, S);
}
}  // namespace

torch::Tensor Trainer::centre(const torch::Tensor& t) const { return centre_square(t, cfg_.data.patch_size_px); }

torch::Tensor Trainer::net_view(const torch::Tensor& t) const {
  return centre_square(t, cfg_.data.patch_size_px + 2 * cfg_.train.network_context_px);
}

model::NetOutput Trainer::to_patch(model::NetOutput o) const {
  for (torch::Tensor* t : {&o.hs, &o.first_stage_hs, &o.inv_depth, &o.depth_m, &o.depth_unit, &o.depth_logits, &o.network_depth_m, &o.reader_depth_m})
    if (t->defined()) *t = centre(*t);
  return o;
}

torch::Tensor Trainer::psf_stack() const {
  if (!psf_still_) return optics::imaging_psf_stack(*psf_, doe_.height(), fixed_psf_);
  return kept_psf_stack();
}

torch::Tensor Trainer::kept_psf_stack() const {
  torch::NoGradGuard no_grad;
  const int64_t version = int64_t(doe_.parameter()._version());
  if (!kept_psf_.defined() || version != kept_psf_version_) {
    kept_psf_ = optics::imaging_psf_stack(*psf_, doe_.height(), fixed_psf_);
    kept_psf_version_ = version;
  }
  return kept_psf_;
}

std::vector<int64_t> Trainer::all_layers() const {
  std::vector<int64_t> v(psf_->spec().depths_m.size());
  for (size_t i = 0; i < v.size(); ++i) v[i] = int64_t(i);
  return v;
}

std::vector<int64_t> Trainer::all_bands() const {
  std::vector<int64_t> v(psf_->spec().wavelengths_m.size());
  for (size_t i = 0; i < v.size(); ++i) v[i] = int64_t(i);
  return v;
}

torch::Tensor Trainer::fused_reader_cost(const torch::Tensor& window) const {
  // The fused reader reads the whole rendered window, as the network's linear
  // inputs do, and is cropped to the network's view: on the patch alone it
  // would see little scene.
  if (!net_->options().fuse_defocus_reader || net_->is_training()) return {};
  return net_view(net_->fusion_reader_cost(window));
}

model::NetOutput Trainer::reconstruct_window(const torch::Tensor& window) {
  const torch::Tensor pre = net_->options().preinverse_layers > 0 ? net_->preinverse(window) : torch::Tensor();
  const torch::Tensor base = net_->options().residual_spectral_wiener ? net_->spectral_wiener(window) : torch::Tensor();
  return to_patch(net_->forward(net_view(window), net_view(pre), net_view(base), fused_reader_cost(window)));
}

void Trainer::refresh_preinverse() {
  const bool pre = net_->options().preinverse_layers > 0, sw = net_->options().residual_spectral_wiener;
  if (!pre && !sw) return;
  refresh_preinverse(psf_stack());
}

void Trainer::refresh_preinverse(const torch::Tensor& all) {
  const bool pre = net_->options().preinverse_layers > 0, sw = net_->options().residual_spectral_wiener;
  torch::NoGradGuard no_grad;
  if (pre) net_->set_preinverse_psf(model::camera_rgb_psfs(all, sensor_.omega));
  if (sw) net_->set_band_psf(all);
}

Batch Trainer::train_batch(int64_t step) const {
  if (!sampler_) throw InputError("trainer: attach_data() first");
  // The global batch's specs (cheap), then only this rank's patches.
  const auto specs = sampler_->draw(cfg_.train.batch_size, mix(cfg_.seed, uint64_t(step)), bank_->size(),
                                    cfg_.data.intensity_min, cfg_.data.intensity_max);
  const int64_t b = cfg_.train.batch_size / world_, first = rank_ * b;
  std::vector<data::Patch> patches;
  for (int64_t i = first; i < first + b; ++i) patches.push_back(sampler_->extract(specs[size_t(i)], bank_.get()));
  Batch out = stack(patches, device_);
  out.first_index = first;
  return out;
}

StepStats Trainer::set_learning_rates(int64_t step) {
  const auto& T = cfg_.train;
  const double f = lr_factor(step, std::max<int64_t>(T.steps, 1), T.warmup_steps, T.decay, T.min_lr_ratio);
  StepStats st;
  st.lr_net = T.lr_net * f;
  st.lr_doe = doe_trained_ ? T.lr_doe_m * f : 0.0;
  auto& groups = opt_->param_groups();
  static_cast<torch::optim::AdamOptions&>(groups[0].options()).lr(st.lr_net);
  if (groups.size() > 1) static_cast<torch::optim::AdamOptions&>(groups[1].options()).lr(st.lr_doe);
  return st;
}

Trainer::StepImage Trainer::render_step(const Batch& batch, int64_t step, optics::PsfProvider provider, bool kept) {
  const auto gens = image_generators(mix(cfg_.seed ^ 0xA5A5A5A5ull, uint64_t(step)), batch.first_index, batch.radiance.size(0));
  const torch::Tensor design = doe_.height();
  const torch::Tensor h = fixed_psf_ ? design : with_fabrication_noise(design, cfg_, doe_, step);
  // The pre-inversion needs every layer's PSFs: computed once (through the
  // provider, so profiling and data-parallel sharing see one call) and handed
  // to the sensor model as slices of the same stack. Under fabrication noise
  // the camera images through the perturbed surface but deconvolves with the
  // design's PSFs, as a fabricated camera that does not know its errors does
  // (and as hsd_fabricate --tolerance evaluates it): those are a second call
  // of the provider; with train.fabrication_noise_calibrated it deconvolves
  // with the perturbed PSFs, as a camera calibrated after fabrication.
  StepImage out;
  if (psf_still_ || (kept && h.is_same(design))) {  // the kept stack: no PSF work, nothing of it in the graph
    const torch::Tensor all = kept_psf_stack();
    if (net_->options().preinverse_layers > 0) out.rgb_psf = model::camera_rgb_psfs(all, sensor_.omega);
    if (net_->options().residual_spectral_wiener) out.band_psf = all;
    provider = optics::fixed_psf_provider(all);
  } else if (net_->options().preinverse_layers > 0 || net_->options().residual_spectral_wiener) {
    auto every_psf = [&](const torch::Tensor& hh) { return provider ? provider(hh, all_layers(), all_bands()) : psf_->compute(hh).psf; };
    const torch::Tensor all = every_psf(h);
    const torch::Tensor known = h.is_same(design) || cfg_.train.fabrication_noise_calibrated ? all : every_psf(design);
    if (net_->options().preinverse_layers > 0)
      out.rgb_psf = model::camera_rgb_psfs(cfg_.train.preinverse_doe_gradient ? known : known.detach(), sensor_.omega);
    if (net_->options().residual_spectral_wiener)
      out.band_psf = cfg_.train.spectral_wiener_doe_gradient ? known : known.detach();
    provider = optics::fixed_psf_provider(all);
  }
  out.image = optics::simulate_sensor(*psf_, sensor_, h, batch.radiance, batch.depth_m, gens, optics::LeaveOut(), provider);
  return out;
}

std::vector<double> Trainer::global_loss_terms(const LossTerms& L, int64_t step) {
  // The mean of the ranks' equal slices: what is logged, and what every rank
  // checks, so all ranks stop together.
  std::vector<double> terms{L.total.item<double>(), L.hs.item<double>(), L.depth.item<double>(), L.tv.item<double>()};
  terms = ranks_->sum(terms, "the loss of step " + std::to_string(step));
  for (double& t : terms) t /= double(world_);
  if (!std::isfinite(terms[0]))
    throw NumericalError("step " + std::to_string(step) + ": the loss is NaN or Inf (cube term " + c10::str(terms[1]) +
                         ", depth term " + c10::str(terms[2]) + ")");
  return terms;
}

void Trainer::apply_gradients(int64_t step) {
  const bool doe_step = doe_learns_at(step);
  ranks_->average_gradients_(doe_step ? trained_parameters() : net_->parameters(),
                             "the gradients of step " + std::to_string(step));
  // A step that leaves the DOE be: no gradient, so Adam skips it (no move,
  // its moments and step count untouched).
  if (doe_trained_ && !doe_step) doe_.parameter().mutable_grad() = torch::Tensor();
  std::vector<std::pair<std::string, torch::Tensor>> named;
  for (const auto& p : net_->named_parameters()) named.emplace_back("network parameter " + p.key(), p.value());
  if (doe_step) named.emplace_back("the DOE height map", doe_.parameter());
  check_grads(named, step);
  // Only the network's gradient norm is clipped: the DOE's gradient is in loss
  // per metre (~1e6 times larger), and Adam's step into it is already bounded
  // by lr_doe_m.
  if (cfg_.train.clip_grad_norm > 0) torch::nn::utils::clip_grad_norm_(net_->parameters(), cfg_.train.clip_grad_norm);
  opt_->step();
}

StepStats Trainer::step(const Batch& batch, int64_t step) {
  hold_in_parameters(false);
  StepStats st = set_learning_rates(step);
  net_->train();
  // Profiling (set_profile) times each phase; the backward pass is then run in
  // three parts (network, sensor, PSF) by cutting the graph at the network's
  // input and at the PSFs: the same chain rule, the same gradients.
  StepProfile* const prof = profile_;
  PhaseTimer timer(prof);
  PsfCuts cuts;
  const optics::PsfProvider& base = fixed_psf_ ? fixed_psf_ : shared_psf_;
  // A step that leaves the DOE be (train.doe_every) renders without a graph
  // into the optics: the network's inputs carry no gradient, as a frozen
  // design's do.
  const bool doe_rests = doe_trained_ && !doe_learns_at(step);
  StepImage si;
  {
    std::optional<torch::NoGradGuard> optics_rest;
    if (doe_rests) optics_rest.emplace();
    si = render_step(batch, step, prof ? cuts.wrap(base, *psf_) : base, doe_rests);
  }
  timer.lap(&StepProfile::sensor_forward);
  if (prof) prof->sensor_forward -= cuts.seconds(), prof->psf_forward += cuts.seconds();
  const torch::Tensor& image = si.image.image;
  const torch::Tensor window = prof && image.requires_grad() ? image.detach().requires_grad_() : image;
  // The whole rendered window's deconvolutions and spectral Wiener base (no
  // wrap-around at the patch), then the network's view of them: the patch and
  // train.network_context_px around it, its outputs cropped to the patch.
  torch::Tensor pre_in;
  if (si.rgb_psf.defined()) {
    net_->set_preinverse_psf(si.rgb_psf);
    pre_in = net_view(net_->preinverse(window));
  }
  torch::Tensor base_in;
  if (si.band_psf.defined()) {
    net_->set_band_psf(si.band_psf);
    // The base's path into the DOE, scaled (train.base_doe_gradient_scale; 1
    // returns the base itself: the same graph).
    base_in = scale_gradient(net_view(net_->spectral_wiener(window)), cfg_.train.base_doe_gradient_scale);
  }
  timer.lap(&StepProfile::inputs_forward);
  const model::NetOutput out = to_patch(net_->forward(net_view(window), pre_in, base_in));
  timer.lap(&StepProfile::network_forward);
  const torch::Tensor truth = centre(batch.radiance);
  LossTerms L =
      reconstruction_loss(out.hs, truth, out.inv_depth, 1.0 / centre(batch.depth_m), weights_, {}, out.depth_logits);
  if (cfg_.train.first_stage_cube_weight > 0.0 && out.first_stage_hs.defined())  // deep supervision of x₁
    L.total = L.total + cfg_.train.first_stage_cube_weight * weights_.alpha * cube_term(out.first_stage_hs, truth, weights_.hs_loss);
  const std::vector<double> terms = global_loss_terms(L, step);
  timer.lap(&StepProfile::loss);
  opt_->zero_grad();
  L.total.backward();
  timer.lap(&StepProfile::network_backward);
  if (prof && window.requires_grad() && window.grad().defined()) {
    image.backward(window.grad());
    timer.lap(&StepProfile::sensor_backward);
    cuts.backward();
    timer.lap(&StepProfile::psf_backward);
  }
  apply_gradients(step);
  update_average(step);
  // The pre-inversion's graph is spent; refresh_preinverse() for the new DOE.
  if (si.rgb_psf.defined()) net_->set_preinverse_psf(si.rgb_psf.detach());
  if (si.band_psf.defined()) net_->set_band_psf(si.band_psf.detach());
  timer.lap(&StepProfile::optimizer);
  if (prof) ++prof->steps;
  st.loss = terms[0], st.hs = terms[1], st.depth = terms[2], st.tv = terms[3];
  return st;
}

ValStats Trainer::validate() {
  if (!val_.radiance.defined()) throw InputError("trainer: attach_data() first");
  hold_in_parameters(true);
  torch::NoGradGuard no_grad;
  // Per-rank batch norm: every rank validates with rank 0's running statistics.
  if (!cfg_.distributed.sync_batch_norm) ranks_->broadcast_(net_->buffers(), "rank 0's batch-norm statistics");
  net_->eval();
  // The PSFs once for every batch (they do not change within a validation).
  const torch::Tensor all = psf_stack();
  refresh_preinverse(all);
  const optics::PsfProvider val_psf = optics::fixed_psf_provider(all);
  const torch::Tensor h = doe_.height();
  // This rank's share [lo, hi) of the validation patches (all of them alone).
  const int64_t n_all = val_.radiance.size(0), B = cfg_.train.batch_size;
  const int64_t lo = n_all * rank_ / world_, hi = n_all * (rank_ + 1) / world_;
  double loss = 0, se = 0, abs_z = 0, se_z = 0, count = 0, px = 0, se_up = 0, abs_c = 0, se_c = 0, sat = 0, se_w = 0;
  const int64_t K = net_->options().preinverse_layers;
  const double c_inv = std::isfinite(baseline_inv_depth_) ? baseline_inv_depth_ : 1.0;
  const double peak = centre(val_.radiance).max().item<double>();
  for (int64_t i = lo; i < hi; i += B) {
    const int64_t b = std::min(B, hi - i);
    const torch::Tensor Iw = val_.radiance.narrow(0, i, b), Zw = val_.depth_m.narrow(0, i, b);
    const optics::SensorImage img =
        optics::simulate_sensor(*psf_, sensor_, h, Iw, Zw, image_generators(mix(cfg_.seed, kValSeed + 1), i, b),
                                optics::LeaveOut(), val_psf);
    const torch::Tensor I = centre(Iw), Z = centre(Zw), J = centre(img.image);
    // The window's deconvolutions once: the network's input and the Wiener baseline (reconstruct_window's work).
    const torch::Tensor pre_view = K > 0 ? net_view(net_->preinverse(img.image)) : torch::Tensor();
    const torch::Tensor pre = K > 0 ? centre(pre_view) : torch::Tensor();
    const torch::Tensor base =
        net_->options().residual_spectral_wiener ? net_view(net_->spectral_wiener(img.image)) : torch::Tensor();
    const model::NetOutput out = to_patch(net_->forward(net_view(img.image), pre_view, base, fused_reader_cost(img.image)));
    se_up += (model::spectral_upsample(upsampling_w_.to(J.device()), J) - I).pow(2).sum().item<double>();
    if (K > 0) {  // the Wiener baseline: the layers' mean deconvolution of the window, upsampled
      const torch::Tensor wm = model::preinverse_layer_mean(pre, K);
      se_w += (model::spectral_upsample(upsampling_w_.to(wm.device()), wm) - I).pow(2).sum().item<double>();
    }
    const torch::Tensor Zc = constant_depth_map(Z, c_inv);
    abs_c += (Zc - Z).abs().sum().item<double>();
    se_c += (Zc - Z).pow(2).sum().item<double>();
    sat += ((out.depth_unit < 0.02) | (out.depth_unit > 0.98)).sum().item<double>();
    loss += reconstruction_loss(out.hs, I, out.inv_depth, 1.0 / Z, weights_, {}, out.depth_logits).total.item<double>() *
            double(b);
    se += (out.hs - I).pow(2).sum().item<double>();
    count += double(I.numel());
    abs_z += (out.depth_m - Z).abs().sum().item<double>();
    se_z += (out.depth_m - Z).pow(2).sum().item<double>();
    px += double(Z.numel());
  }
  net_->train();
  {
    const auto s = ranks_->sum({loss, se, count, abs_z, se_z, px, se_up, abs_c, se_c, sat, se_w}, "validation sums");
    loss = s[0], se = s[1], count = s[2], abs_z = s[3], se_z = s[4], px = s[5];
    se_up = s[6], abs_c = s[7], se_c = s[8], sat = s[9], se_w = s[10];
  }
  ValStats v;
  v.loss = loss / double(n_all);
  v.peak = peak;
  v.hs_psnr_db = 10.0 * std::log10(peak * peak / std::max(se / count, 1e-30));
  v.depth_rmse_m = std::sqrt(se_z / px);
  v.depth_mae_m = abs_z / px;
  v.baseline_hs_psnr_db = 10.0 * std::log10(peak * peak / std::max(se_up / count, 1e-30));
  if (K > 0) v.baseline_wiener_hs_psnr_db = 10.0 * std::log10(peak * peak / std::max(se_w / count, 1e-30));
  v.baseline_depth_rmse_m = std::sqrt(se_c / px);
  v.baseline_depth_mae_m = abs_c / px;
  v.depth_saturated = sat / px;
  return v;
}

void Trainer::save_checkpoint(const std::string& path, int64_t next_step) {
  hold_in_parameters(true);  // the model; the optimiser's weights beside it
  NamedTensors extra;  // the optimiser's weights (live.*) and the illuminant reader's moments
  const std::vector<std::string> names = trained_names();
  for (size_t i = 0; i < average_.size(); ++i) extra.emplace_back("live." + names[i], average_[i]);
  if (net_->illuminant_moments().mean.defined())
    for (auto& e : illuminant_entries(net_->illuminant_moments())) extra.push_back(std::move(e));
  write_checkpoint(path, doe_, net_, *opt_, baseline_inv_depth_, next_step, extra);
}

void Trainer::ensure_illuminant_moments() {
  if (!net_->options().read_illuminant || net_->illuminant_moments().mean.defined()) return;
  if (!data::has_manifest(cfg_.data.root) || data::read_manifest(cfg_.data.root).split("train").empty()) {
    log::warn("model.read_illuminant: " + cfg_.data.root + " has no training split to read the reflectance statistics "
              "from; the cube's base keeps the equal-weight prior of the training lights");
    net_->disable_illuminant_reader();
    return;
  }
  give_illuminant_moments(data::load_split(cfg_.data.root, "train", cfg_.optics.wavelengths_m(),
                                           cfg_.optics.band_width_m(), cfg_.data.loader_threads));
}

void Trainer::give_illuminant_moments(const std::vector<data::LoadedScene>& train_scenes) {
  for (const auto& sc : train_scenes)
    if (sc.scene.kind != data::SpectralKind::Reflectance) {
      if (!net_->options().read_illuminant) return;
      log::warn("model.read_illuminant: " + sc.file + " of the training split is a radiance, not a reflectance (its "
                "light cannot be taken out); the cube's base keeps the equal-weight prior of the training lights");
      net_->disable_illuminant_reader();
      return;
    }
  net_->set_illuminant_moments(training_illuminant_moments(train_scenes, cfg_));
}

int64_t Trainer::load_checkpoint(const std::string& path) {
  TrainingState state{doe_, net_, *opt_, baseline_inv_depth_};
  std::vector<torch::Tensor> live;  // the optimiser's weights, when the file has them
  if (cfg_.train.ema_decay > 0.0) {
    const std::vector<std::string> names = trained_names();
    for (const auto& p : trained_parameters()) live.push_back(torch::empty_like(p.detach()));
    for (size_t i = 0; i < live.size(); ++i) state.live.emplace_back("live." + names[i], live[i]);
  }
  const int64_t next = read_checkpoint(path, state);
  // The reader's moments it was trained with; a config naming another number
  // of lights asks for others (ensure_illuminant_moments makes them from data.root).
  const int64_t lights = int64_t(cfg_.data.illuminants.size());
  const bool stored = state.illuminant.mean.defined();
  if (stored && state.illuminant.mean.size(0) == lights)
    net_->set_illuminant_moments(state.illuminant);
  else if (stored && net_->options().read_illuminant)
    log::warn(path + " holds the illuminant reader's moments of " + std::to_string(state.illuminant.mean.size(0)) +
              " lights but data.illuminants names " + std::to_string(lights) +
              ": the reader takes them from the training split of data.root instead");
  if (cfg_.train.ema_decay > 0.0) {  // the parameters hold the file's model; its optimiser's weights go aside
    if (state.live_read)
      average_ = live;
    else
      reset_average();  // a file without them (averaging off when written): both are its model
    average_in_use_ = true;
  }
  // Every rank read a checkpoint of the same step, then all take rank 0's values.
  const auto all = ranks_->gather(double(next), "the resumed step");
  for (int64_t r = 0; r < world_; ++r)
    if (all[size_t(r)] != all[0])
      throw DistributedError("rank " + std::to_string(r) + " resumed from step " + c10::str(int64_t(all[size_t(r)])) +
                             " but rank 0 from step " + c10::str(int64_t(all[0])) + " (" + path +
                             " differs between the ranks' hosts)");
  ranks_->broadcast_(replicated_state(), "the resumed network, DOE and Adam state");
  refresh_preinverse();  // the loaded DOE's PSFs
  return next;
}

void Trainer::write_val_pictures(const std::string& dir, int64_t step) {
  hold_in_parameters(true);
  torch::NoGradGuard no_grad;
  net_->eval();
  refresh_preinverse();
  const int64_t n = std::min<int64_t>(2, val_.radiance.size(0));
  const optics::SensorImage img = optics::simulate_sensor(
      *psf_, sensor_, doe_.height(), val_.radiance.narrow(0, 0, n), val_.depth_m.narrow(0, 0, n),
      image_generators(mix(cfg_.seed, kValSeed + 1), 0, n), optics::LeaveOut(), fixed_psf_);
  ValidationPictures v;
  v.truth = centre(val_.radiance.narrow(0, 0, n));
  v.depth_m = centre(val_.depth_m.narrow(0, 0, n));
  v.sensor = centre(img.image);
  v.out = reconstruct_window(img.image);
  net_->train();
  v.wavelengths_m = cfg_.optics.wavelengths_m();
  v.band_width_m = cfg_.optics.band_width_m();
  const auto& g = cfg_.data.generator;
  v.near_m = std::min(g.depth_min_m, cfg_.optics.depths_m.front());
  v.far_m = std::max(g.depth_max_m, cfg_.optics.depths_m.back());
  v.psf = psf_stack();
  v.depths_m = psf_->spec().depths_m;
  char stem[64];
  std::snprintf(stem, sizeof stem, "/step_%06lld_", (long long)step);
  write_validation_pictures(dir + stem, v);
}

void Trainer::start_from(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) input_error(path, "no such checkpoint file (train.init_checkpoint)");
  read_network_weights(path, net_);
  network_started_ = true;
  reset_average();
  log::info("network weights from " + path + " (train.init_checkpoint); DOE, optimizer and step start afresh");
}

void Trainer::check_resume(const std::string& out_dir) {
  const std::string ckpt = out_dir + "/checkpoints/last.pt";
  if (!std::filesystem::is_regular_file(ckpt)) input_error(ckpt, "no checkpoint to resume from (--resume)");
  const int64_t start = load_checkpoint(ckpt);
  if (writes_outputs()) MetricsLog::check_resumable(out_dir + "/metrics.csv", start);
}

namespace {

// The log line of a validation, its baselines beside each figure.
std::string validation_line(int64_t step, const ValStats& v) {
  char buf[400], wb[64] = "";
  if (std::isfinite(v.baseline_wiener_hs_psnr_db))
    std::snprintf(wb, sizeof wb, "; Wiener + upsampling %.2f dB", v.baseline_wiener_hs_psnr_db);
  std::snprintf(buf, sizeof buf,
                "validation at step %lld: HS PSNR %.2f dB (upsampling alone %.2f dB%s); depth RMSE %.3f m (constant "
                "depth %.3f m), MAE %.3f m (%.3f m); depth sigmoid saturated at %.1f%% of pixels",
                (long long)step, v.hs_psnr_db, v.baseline_hs_psnr_db, wb, v.depth_rmse_m, v.baseline_depth_rmse_m,
                v.depth_mae_m, v.baseline_depth_mae_m, 100.0 * v.depth_saturated);
  return buf;
}

}  // namespace

void Trainer::record_validation(MetricsLog& metrics, int64_t step, const std::string& val_dir, bool log_line) {
  const ValStats v = validate();
  metrics.set_val(v);
  if (!writes_outputs()) return;
  if (log_line) log::info(validation_line(step, v));
  write_val_pictures(val_dir, step);
}

std::string Trainer::progress_suffix(double loss, double seconds, int64_t steps, double collective_seconds) const {
  char sfx[128];
  const double per = seconds / double(std::max<int64_t>(steps, 1));
  if (world_ > 1)
    std::snprintf(sfx, sizeof sfx, "loss %.4g  %.2f s/step  %.0f%% in collectives", loss, per,
                  100.0 * collective_seconds / std::max(1e-9, seconds));
  else
    std::snprintf(sfx, sizeof sfx, "loss %.4g  %.2f s/step", loss, per);
  return sfx;
}

void Trainer::run(const std::string& out_dir, bool resume) {
  const auto& T = cfg_.train;
  const std::string ckpt_dir = out_dir + "/checkpoints", val_dir = out_dir + "/val";
  const std::string ckpt = ckpt_dir + "/last.pt";
  const bool writer = writes_outputs();
  if (writer) {
    make_dirs(ckpt_dir);
    make_dirs(val_dir);
  }
  int64_t start = 0;
  MetricsLog metrics(writer ? out_dir : std::string());
  double wall_offset = 0.0;
  if (resume) {
    start = load_checkpoint(ckpt);
    wall_offset = metrics.resume(start);
    log::info("resuming from " + ckpt + " at step " + std::to_string(start));
  }
  std::unique_ptr<log::Progress> progress;
  if (writer) {
    progress = std::make_unique<log::Progress>("train", long(T.steps));
    progress->set_start(long(start));
    log::info("network arithmetic in training steps: " + precision_.why);
  }
  if (world_ > 1)
    log::info("data-parallel: " + std::to_string(world_) + " ranks x " + std::to_string(T.batch_size / world_) +
              " patches = global batch " + std::to_string(T.batch_size));
  const auto t0 = std::chrono::steady_clock::now();
  auto wall = [&] { return wall_offset + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  // Data loading overlaps compute: the next batch is made while this step runs.
  std::future<Batch> next;
  if (start < T.steps) next = std::async(std::launch::async, [this, start] { return train_batch(start); });
  const double rate_t = wall(), comm_t = ranks_->seconds_communicating();
  if (start == 0 && T.steps > 0) {  // where validation starts from
    metrics.add_row(0, 0.0);
    record_validation(metrics, 0, val_dir, true);
    metrics.write();
  }
  for (int64_t k = start; k < T.steps; ++k) {
    const Batch b = next.get();
    if (k + 1 < T.steps) next = std::async(std::launch::async, [this, k] { return train_batch(k + 1); });
    const StepStats st = step(b, k);
    const bool last = k + 1 == T.steps;
    const bool do_val = (k + 1) % T.val_every == 0 || last;
    if ((k + 1) % T.log_every == 0 || do_val || k == start) {
      metrics.add_row(k + 1, wall());
      metrics.set_train(st);
      if (do_val) record_validation(metrics, k + 1, val_dir, last);
      metrics.write();
    }
    if ((k + 1) % T.checkpoint_every == 0 || last) {
      check_replicas_agree(k + 1);
      if (writer) save_checkpoint(ckpt, k + 1);
    }
    if (progress) {
      progress->set_suffix(
          progress_suffix(st.loss, wall() - rate_t, k + 1 - start, ranks_->seconds_communicating() - comm_t));
      progress->step();
    }
  }
  if (progress) progress->finish();
  hold_in_parameters(true);  // the trainer holds the model, as its checkpoint does
  refresh_preinverse();
  ranks_->barrier("at the end of training");  // every rank leaves once rank 0's last checkpoint is written
  if (start >= T.steps) log::info("nothing to do: the checkpoint is at step " + std::to_string(start));
}

}  // namespace hsd::train
