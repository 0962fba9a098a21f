#include "train/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/tensor_io.h"
#include "data/image_io.h"
#include "data/preview.h"
#include "data/synthetic_dataset.h"
#include "model/spectral_upsampling.h"
#include "optics/psf_atlas.h"
#include "train/metrics_csv.h"
#include "train/plot.h"
#include "train/schedule.h"

namespace hsd::train {

namespace {

uint64_t mix(uint64_t a, uint64_t b) {
  uint64_t x = a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E019ull + (a << 6) + (a >> 2));
  x ^= x >> 31;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 29;
  return x;
}
constexpr uint64_t kValSeed = 0x5EEDULL;

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

model::NetOptions net_options(const Config& cfg) {
  model::NetOptions o;
  o.bands = int64_t(cfg.optics.wavelengths_nm.size());
  o.base_width = cfg.model.base_width;
  o.levels = cfg.model.levels;
  o.norm = cfg.model.norm;
  const auto& d = cfg.optics.depths_m;
  o.depth_min_m = std::min(*std::min_element(d.begin(), d.end()), cfg.data.generator.depth_min_m);
  o.depth_max_m = std::max(*std::max_element(d.begin(), d.end()), cfg.data.generator.depth_max_m);
  return o;
}

Batch stack(const std::vector<data::Patch>& patches, torch::Device device) {
  std::vector<torch::Tensor> r, d;
  for (const auto& p : patches) r.push_back(p.spectral), d.push_back(p.depth_m);
  return {torch::stack(r).to(device), torch::stack(d).to(device)};
}

void check_grads(const std::vector<std::pair<std::string, torch::Tensor>>& params, int64_t step) {
  for (const auto& [name, p] : params)
    if (p.grad().defined() && !torch::isfinite(p.grad()).all().item<bool>())
      throw NumericalError("step " + std::to_string(step) + ": the gradient of " + name +
                           " holds NaN or Inf (lower train.lr_net/lr_doe_m or check the data)");
}

}  // namespace

Trainer::Trainer(const Config& cfg)
    : cfg_(cfg),
      device_(resolve_device(cfg.device)),
      material_(optics::Material::load(cfg.optics.material)),
      psf_(std::make_unique<optics::PsfSimulator>(optics::make_psf_spec(cfg.optics, material_, device_))),
      sensor_(optics::make_sensor_model(cfg.sensor, psf_->spec(), cfg.optics.band_width_m())),
      doe_(optics::make_doe(cfg.optics, material_, cfg.seed, device_)) {
  torch::manual_seed(int64_t(cfg.seed));  // network initialisation
  const torch::Tensor w = model::spectral_upsampling_weights(sensor_.omega.cpu());
  net_ = model::HsdNet(net_options(cfg), w);
  net_->to(device_);
  weights_ = {cfg.train.loss_alpha, cfg.train.loss_beta, cfg.train.loss_gamma};
  std::vector<torch::optim::OptimizerParamGroup> groups;
  groups.emplace_back(net_->parameters(), std::make_unique<torch::optim::AdamOptions>(cfg.train.lr_net));
  if (cfg.train.freeze_doe) {
    doe_.parameter().set_requires_grad(false);
  } else {
    groups.emplace_back(std::vector<torch::Tensor>{doe_.parameter()},
                        std::make_unique<torch::optim::AdamOptions>(cfg.train.lr_doe_m));
  }
  opt_ = std::make_unique<torch::optim::Adam>(std::move(groups), torch::optim::AdamOptions(cfg.train.lr_net));
}

void Trainer::attach_data() {
  const std::string root = data::ensure_dataset(cfg_);
  const auto bands = cfg_.optics.wavelengths_m();
  const double bw = cfg_.optics.band_width_m();
  train_scenes_ = data::load_split(root, "train", bands, bw, cfg_.data.loader_threads);
  const data::Manifest m = data::read_manifest(root);
  bank_ = std::make_unique<data::IlluminantBank>(cfg_.data.illuminants, bands, bw);
  sampler_ = std::make_unique<data::PatchSampler>(train_scenes_, cfg_.data.patch_size_px);
  // Validation: the val split (the train split with other patches if there is none).
  std::unique_ptr<data::PatchSampler> val_sampler;
  if (!m.split("val").empty()) {
    val_scenes_ = data::load_split(root, "val", bands, bw, cfg_.data.loader_threads);
    val_sampler = std::make_unique<data::PatchSampler>(val_scenes_, cfg_.data.patch_size_px);
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
            std::to_string(cfg_.data.patch_size_px) + " px");
}

Batch Trainer::train_batch(int64_t step) const {
  if (!sampler_) throw InputError("trainer: attach_data() first");
  std::vector<data::Patch> patches;
  for (const auto& s : sampler_->draw(cfg_.train.batch_size, mix(cfg_.seed, uint64_t(step)), bank_->size(),
                                      cfg_.data.intensity_min, cfg_.data.intensity_max))
    patches.push_back(sampler_->extract(s, bank_.get()));
  return stack(patches, device_);
}

StepStats Trainer::step(const Batch& batch, int64_t step) {
  const auto& T = cfg_.train;
  const double f = lr_factor(step, std::max<int64_t>(T.steps, 1), T.warmup_steps, T.decay, T.min_lr_ratio);
  StepStats st;
  st.lr_net = T.lr_net * f;
  st.lr_doe = T.freeze_doe ? 0.0 : T.lr_doe_m * f;
  auto& groups = opt_->param_groups();
  static_cast<torch::optim::AdamOptions&>(groups[0].options()).lr(st.lr_net);
  if (groups.size() > 1) static_cast<torch::optim::AdamOptions&>(groups[1].options()).lr(st.lr_doe);

  net_->train();
  auto gen = at::detail::createCPUGenerator(mix(cfg_.seed ^ 0xA5A5A5A5ull, uint64_t(step)));
  const torch::Tensor h = doe_.height();
  const optics::SensorImage img = optics::simulate_sensor(*psf_, sensor_, h, batch.radiance, batch.depth_m, gen);
  const model::NetOutput out = net_->forward(img.image);
  const LossTerms L = reconstruction_loss(out.hs, batch.radiance, out.inv_depth, 1.0 / batch.depth_m, weights_);
  if (!std::isfinite(L.total.item<double>()))
    throw NumericalError("step " + std::to_string(step) + ": the loss is NaN or Inf (cube term " +
                         c10::str(L.hs.item<double>()) + ", depth term " + c10::str(L.depth.item<double>()) + ")");
  opt_->zero_grad();
  L.total.backward();
  std::vector<std::pair<std::string, torch::Tensor>> named;
  for (const auto& p : net_->named_parameters()) named.emplace_back("network parameter " + p.key(), p.value());
  if (!T.freeze_doe) named.emplace_back("the DOE height map", doe_.parameter());
  check_grads(named, step);
  // Clipping per group: the network's gradient norm, and the DOE's relative to
  // its own scale (its gradient is in loss per metre, ~1e6 times larger).
  if (T.clip_grad_norm > 0) torch::nn::utils::clip_grad_norm_(net_->parameters(), T.clip_grad_norm);
  opt_->step();
  st.loss = L.total.item<double>();
  st.hs = L.hs.item<double>();
  st.depth = L.depth.item<double>();
  st.tv = L.tv.item<double>();
  return st;
}

ValStats Trainer::validate() {
  if (!val_.radiance.defined()) throw InputError("trainer: attach_data() first");
  torch::NoGradGuard no_grad;
  net_->eval();
  auto gen = at::detail::createCPUGenerator(mix(cfg_.seed, kValSeed + 1));
  const torch::Tensor h = doe_.height();
  const int64_t n = val_.radiance.size(0), B = cfg_.train.batch_size;
  double loss = 0, se = 0, abs_z = 0, se_z = 0, count = 0, px = 0;
  const double peak = val_.radiance.max().item<double>();
  for (int64_t i = 0; i < n; i += B) {
    const int64_t b = std::min(B, n - i);
    const torch::Tensor I = val_.radiance.narrow(0, i, b), Z = val_.depth_m.narrow(0, i, b);
    const optics::SensorImage img = optics::simulate_sensor(*psf_, sensor_, h, I, Z, gen);
    const model::NetOutput out = net_->forward(img.image);
    loss += reconstruction_loss(out.hs, I, out.inv_depth, 1.0 / Z, weights_).total.item<double>() * double(b);
    se += (out.hs - I).pow(2).sum().item<double>();
    count += double(I.numel());
    abs_z += (out.depth_m - Z).abs().sum().item<double>();
    se_z += (out.depth_m - Z).pow(2).sum().item<double>();
    px += double(Z.numel());
  }
  net_->train();
  ValStats v;
  v.loss = loss / double(n);
  v.peak = peak;
  v.hs_psnr_db = 10.0 * std::log10(peak * peak / std::max(se / count, 1e-30));
  v.depth_rmse_m = std::sqrt(se_z / px);
  v.depth_mae_m = abs_z / px;
  return v;
}

void Trainer::save_checkpoint(const std::string& path, int64_t next_step) const {
  TensorDict d;
  d["step"] = torch::tensor(next_step, torch::kInt64);
  d["doe.raw"] = doe_.parameter().detach().cpu();
  d["height_map_m"] = doe_.height().detach().to(torch::kFloat32).cpu();
  d["doe_pitch_m"] = torch::tensor(doe_.pitch_m(), torch::kFloat64);
  for (const auto& p : net_->named_parameters()) d["net." + p.key()] = p.value().detach().cpu();
  for (const auto& b : net_->named_buffers()) d["net." + b.key()] = b.value().detach().cpu();
  const auto& groups = opt_->param_groups();
  const auto& state = opt_->state();
  for (size_t g = 0; g < groups.size(); ++g)
    for (size_t i = 0; i < groups[g].params().size(); ++i) {
      const auto it = state.find(c10::guts::to_string(groups[g].params()[i].unsafeGetTensorImpl()));
      if (it == state.end()) continue;
      const auto& s = static_cast<const torch::optim::AdamParamState&>(*it->second);
      const std::string k = "adam." + std::to_string(g) + "." + std::to_string(i) + ".";
      d[k + "exp_avg"] = s.exp_avg().cpu();
      d[k + "exp_avg_sq"] = s.exp_avg_sq().cpu();
      d[k + "step"] = torch::tensor(s.step(), torch::kInt64);
    }
  save_tensor_dict(path, d);
}

int64_t Trainer::load_checkpoint(const std::string& path) {
  const TensorDict d = load_tensor_dict(path);
  torch::NoGradGuard no_grad;
  auto copy_into = [&](torch::Tensor& dst, const std::string& key) {
    const torch::Tensor src = dict_get(d, key, path);
    if (src.sizes() != dst.sizes())
      input_error(path, key + " is " + c10::str(src.sizes()) + " but the config builds " + c10::str(dst.sizes()) +
                            " (a checkpoint of another config?)");
    dst.copy_(src.to(dst.device(), dst.scalar_type()));
  };
  copy_into(doe_.parameter(), "doe.raw");
  for (auto& p : net_->named_parameters()) copy_into(p.value(), "net." + p.key());
  for (auto& b : net_->named_buffers()) copy_into(b.value(), "net." + b.key());
  auto& groups = opt_->param_groups();
  auto& state = opt_->state();
  state.clear();
  for (size_t g = 0; g < groups.size(); ++g)
    for (size_t i = 0; i < groups[g].params().size(); ++i) {
      const std::string k = "adam." + std::to_string(g) + "." + std::to_string(i) + ".";
      if (!d.count(k + "exp_avg")) continue;
      const torch::Tensor& p = groups[g].params()[i];
      auto s = std::make_unique<torch::optim::AdamParamState>();
      s->exp_avg(d.at(k + "exp_avg").to(p.device(), p.scalar_type()).clone());
      s->exp_avg_sq(d.at(k + "exp_avg_sq").to(p.device(), p.scalar_type()).clone());
      s->step(d.at(k + "step").item<int64_t>());
      if (s->exp_avg().sizes() != p.sizes()) input_error(path, k + "exp_avg does not match its parameter");
      state[c10::guts::to_string(p.unsafeGetTensorImpl())] = std::move(s);
    }
  return dict_get(d, "step", path).item<int64_t>();
}

void Trainer::write_val_pictures(const std::string& dir, int64_t step) {
  torch::NoGradGuard no_grad;
  net_->eval();
  const int64_t n = std::min<int64_t>(2, val_.radiance.size(0));
  const torch::Tensor I = val_.radiance.narrow(0, 0, n), Z = val_.depth_m.narrow(0, 0, n);
  auto gen = at::detail::createCPUGenerator(mix(cfg_.seed, kValSeed + 1));
  const optics::SensorImage img = optics::simulate_sensor(*psf_, sensor_, doe_.height(), I, Z, gen);
  const model::NetOutput out = net_->forward(img.image);
  net_->train();
  const auto bands = cfg_.optics.wavelengths_m();
  const double bw = cfg_.optics.band_width_m();
  char stem[64];
  std::snprintf(stem, sizeof stem, "%s/step_%06lld_", dir.c_str(), (long long)step);
  const torch::Tensor truth0 = data::spectral_to_linear_srgb(I[0].cpu(), bands, bw);
  const double white = std::max(1e-6, truth0.max().item<double>());
  const auto& g = cfg_.data.generator;
  const double near = std::min(g.depth_min_m, cfg_.optics.depths_m.front()), far = std::max(g.depth_max_m, cfg_.optics.depths_m.back());
  std::vector<std::string> parts;
  for (int64_t k = 0; k < n; ++k) {
    const std::string p = std::string(stem) + std::to_string(k) + "_";
    for (const char* f : {"truth_srgb", "sensor", "recon_srgb", "error_hs", "truth_depth", "recon_depth"})
      parts.push_back(p + f + ".png");
    data::write_srgb_png(p + "truth_srgb.png", k == 0 ? truth0 : data::spectral_to_linear_srgb(I[k].cpu(), bands, bw), white);
    data::write_srgb_png(p + "recon_srgb.png", data::spectral_to_linear_srgb(out.hs[k].clamp_min(0).cpu(), bands, bw), white);
    data::write_srgb_png(p + "sensor.png", img.image[k].cpu(), std::max(1e-6, img.image[k].max().item<double>()));
    data::write_depth_png(p + "truth_depth.png", Z[k].cpu(), {}, near, far);
    data::write_depth_png(p + "recon_depth.png", out.depth_m[k].cpu(), {}, near, far);
    // Error map: |Î − I| averaged over bands, as grey scaled to the patch's peak radiance / 4.
    const torch::Tensor err = (out.hs[k] - I[k]).abs().mean(0).cpu();
    data::write_srgb_png(p + "error_hs.png", err.unsqueeze(0).expand({3, -1, -1}), std::max(1e-6, 0.25 * I[k].max().item<double>()));
  }
  // One picture per validation: a row per patch, [truth | sensor | reconstruction |
  // |error| | true depth | predicted depth], enlarged 3x; the pieces are removed.
  write_montage(parts, 6, 3.0, std::string(stem) + "reconstructions.png");
  optics::write_psf_atlas(std::string(stem) + "psf_atlas.png", psf_->compute(doe_.height().detach()).psf.cpu(),
                          psf_->spec().wavelengths_m, psf_->spec().depths_m);
}

void Trainer::run(const std::string& out_dir, bool resume) {
  const auto& T = cfg_.train;
  const std::string ckpt_dir = out_dir + "/checkpoints", val_dir = out_dir + "/val";
  const std::string ckpt = ckpt_dir + "/last.pt", csv = out_dir + "/metrics.csv";
  make_dirs(ckpt_dir);
  make_dirs(val_dir);
  int64_t start = 0;
  // Rows of metrics.csv: kept in memory, the file rewritten atomically.
  const std::string header =
      "step,wall_s,train_loss,val_loss,train_hs_l1,train_depth_l1,lr_net,lr_doe_m,val_hs_psnr_db,val_depth_rmse_m,val_depth_mae_m";
  std::vector<std::vector<std::string>> rows;  // cells; empty where not measured
  double wall_offset = 0.0;
  if (resume) {
    if (!std::filesystem::exists(ckpt)) input_error(ckpt, "no checkpoint to resume from (--resume)");
    start = load_checkpoint(ckpt);
    for (const auto& c : read_csv_rows(csv))
      if (c.size() > 1 && std::stoll(c[0]) <= start) {  // rows up to the checkpoint's step were written before it
        rows.push_back(c);
        wall_offset = std::stod(c[1]);
      }
    log::info("resuming from " + ckpt + " at step " + std::to_string(start));
  }
  auto write_outputs = [&] {
    std::string text = header + "\n";
    std::vector<double> xs, tr, vx, vl, psnr;
    for (const auto& c : rows) {
      for (size_t i = 0; i < c.size(); ++i) text += (i ? "," : "") + c[i];
      text += "\n";
      xs.push_back(std::stod(c[0]));
      tr.push_back(c[2].empty() ? NAN : std::stod(c[2]));
      if (!c[3].empty()) vx.push_back(std::stod(c[0])), vl.push_back(std::stod(c[3])), psnr.push_back(std::stod(c[8]));
    }
    write_text_file(csv, text);
    write_line_plot(out_dir + "/curves.png", "loss (L1 cube + weighted depth terms)", "step",
                    {{"train", xs, tr, {200, 120, 30}}, {"validation", vx, vl, {30, 30, 200}}}, true);
    if (!vx.empty())
      write_line_plot(out_dir + "/val_psnr.png", "validation hyperspectral PSNR [dB]", "step",
                      {{"PSNR", vx, psnr, {30, 140, 30}}}, false);
  };

  log::Progress progress("train", long(T.steps));
  progress.set_start(long(start));
  const auto t0 = std::chrono::steady_clock::now();
  auto wall = [&] { return wall_offset + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  // Data loading overlaps compute: the next batch is made while this step runs.
  std::future<Batch> next;
  if (start < T.steps) next = std::async(std::launch::async, [this, start] { return train_batch(start); });
  double rate_t = wall();
  int64_t rate_n = 0;
  if (start == 0 && T.steps > 0) {  // where validation starts from
    const ValStats v = validate();
    rows.push_back({"0", "0.000", "", fmt("%.6g", v.loss), "", "", "", "", fmt("%.4f", v.hs_psnr_db),
                    fmt("%.5f", v.depth_rmse_m), fmt("%.5f", v.depth_mae_m)});
    write_val_pictures(val_dir, 0);
    write_outputs();
  }
  for (int64_t k = start; k < T.steps; ++k) {
    const Batch b = next.get();
    if (k + 1 < T.steps) next = std::async(std::launch::async, [this, k] { return train_batch(k + 1); });
    const StepStats st = step(b, k);
    ++rate_n;
    const bool last = k + 1 == T.steps;
    const bool do_val = (k + 1) % T.val_every == 0 || last;
    if ((k + 1) % T.log_every == 0 || do_val || k == start) {
      std::vector<std::string> row{std::to_string(k + 1), fmt("%.3f", wall()), fmt("%.6g", st.loss), "",
                                   fmt("%.6g", st.hs), fmt("%.6g", st.depth), fmt("%.4g", st.lr_net),
                                   fmt("%.4g", st.lr_doe), "", "", ""};
      if (do_val) {
        const ValStats v = validate();
        row[3] = fmt("%.6g", v.loss), row[8] = fmt("%.4f", v.hs_psnr_db);
        row[9] = fmt("%.5f", v.depth_rmse_m), row[10] = fmt("%.5f", v.depth_mae_m);
      }
      rows.push_back(row);
      if (do_val) write_val_pictures(val_dir, k + 1);
      write_outputs();
    }
    if ((k + 1) % T.checkpoint_every == 0 || last) save_checkpoint(ckpt, k + 1);
    const double now = wall();
    char sfx[96];
    std::snprintf(sfx, sizeof sfx, "loss %.4g  %.2f s/step", st.loss, (now - rate_t) / double(std::max<int64_t>(rate_n, 1)));
    progress.set_suffix(sfx);
    progress.step();
  }
  progress.finish();
  if (start >= T.steps) log::info("nothing to do: the checkpoint is at step " + std::to_string(start));
}

}  // namespace hsd::train
