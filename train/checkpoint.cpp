#include "train/checkpoint.h"

#include <cmath>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "common/error.h"
#include "common/tensor_io.h"

namespace hsd::train {

namespace {

// A loaded dict whose entries are read checked: InputError naming the file and the entry.
struct CheckedDict {
  TensorDict d;
  std::string path;

  torch::Tensor entry(const std::string& key, c10::IntArrayRef shape, const std::string& mismatch_hint) const {
    const torch::Tensor t = dict_get(d, key, path);
    if (t.sizes() != shape)
      input_error(path, key + " is " + c10::str(t.sizes()) + " but the config builds " + c10::str(shape) + " (" + mismatch_hint + ")");
    const std::string bad = first_nonfinite(t);
    if (!bad.empty()) input_error(path, key + " holds " + bad);
    return t;
  }
  double scalar(const std::string& key) const {
    const torch::Tensor t = dict_get(d, key, path);
    if (t.numel() != 1) input_error(path, key + " must be one number, is " + c10::str(t.sizes()));
    const double v = t.to(torch::kFloat64).item<double>();
    if (!std::isfinite(v)) input_error(path, key + " is not finite");
    return v;
  }
  int64_t count(const std::string& key) const {
    const double v = scalar(key);
    if (!(v >= 0 && v == std::floor(v) && v < 9e15)) input_error(path, key + " must be a whole number >= 0, is " + c10::str(v));
    return int64_t(v);
  }
};

using Copies = std::vector<std::pair<torch::Tensor, torch::Tensor>>;  // (destination, checked source)

void add_network(const CheckedDict& d, model::HsdNet& net, Copies& copies, const std::string& hint) {
  for (auto& p : net->named_parameters()) copies.emplace_back(p.value(), d.entry("net." + p.key(), p.value().sizes(), hint));
  for (auto& b : net->named_buffers()) copies.emplace_back(b.value(), d.entry("net." + b.key(), b.value().sizes(), hint));
}

void apply(Copies& copies) {
  for (auto& [dst, src] : copies) dst.copy_(src.to(dst.device(), dst.scalar_type()));
}

const char* kOtherConfig = "a checkpoint of another config?";

}  // namespace

NamedTensors illuminant_entries(const model::IlluminantMoments& m) {
  return {{"illuminant.mean", m.mean.to(torch::kFloat64)},
          {"illuminant.second", m.second.to(torch::kFloat64)},
          {"illuminant.intensity_range", torch::tensor({m.intensity_min, m.intensity_max}, torch::kFloat64)}};
}

void write_checkpoint(const std::string& path, const optics::Doe& doe, const model::HsdNet& net, const torch::optim::Adam& adam,
                      double baseline_inv_depth, int64_t next_step, const NamedTensors& extra) {
  TensorDict d;
  for (const auto& [name, t] : extra) d[name] = t.detach().cpu();
  d["step"] = torch::tensor(next_step, torch::kInt64);
  d["doe.raw"] = doe.parameter().detach().cpu();
  d["height_map_m"] = doe.height().detach().to(torch::kFloat32).cpu();
  d["doe_pitch_m"] = torch::tensor(doe.pitch_m(), torch::kFloat64);
  if (std::isfinite(baseline_inv_depth)) d["baseline.inv_depth_per_m"] = torch::tensor(baseline_inv_depth, torch::kFloat64);
  for (const auto& p : net->named_parameters()) d["net." + p.key()] = p.value().detach().cpu();
  for (const auto& b : net->named_buffers()) d["net." + b.key()] = b.value().detach().cpu();
  const auto& groups = adam.param_groups();
  const auto& state = adam.state();
  for (size_t g = 0; g < groups.size(); ++g)
    for (size_t i = 0; i < groups[g].params().size(); ++i) {
      const auto it = state.find(c10::guts::to_string(groups[g].params()[i].unsafeGetTensorImpl()));
      if (it == state.end()) continue;
      const auto& st = static_cast<const torch::optim::AdamParamState&>(*it->second);
      const std::string k = "adam." + std::to_string(g) + "." + std::to_string(i) + ".";
      d[k + "exp_avg"] = st.exp_avg().cpu();
      d[k + "exp_avg_sq"] = st.exp_avg_sq().cpu();
      d[k + "step"] = torch::tensor(st.step(), torch::kInt64);
    }
  save_tensor_dict(path, d);
}

int64_t read_checkpoint(const std::string& path, TrainingState& s) {
  const CheckedDict d{load_tensor_dict(path), path};
  torch::NoGradGuard no_grad;
  Copies copies;
  copies.emplace_back(s.doe.parameter(), d.entry("doe.raw", s.doe.parameter().sizes(), kOtherConfig));
  add_network(d, s.net, copies, kOtherConfig);
  auto& groups = s.adam.param_groups();
  std::vector<std::pair<torch::Tensor, std::unique_ptr<torch::optim::AdamParamState>>> adam;
  for (size_t g = 0; g < groups.size(); ++g)
    for (size_t i = 0; i < groups[g].params().size(); ++i) {
      const std::string k = "adam." + std::to_string(g) + "." + std::to_string(i) + ".";
      if (!d.d.count(k + "exp_avg") && !d.d.count(k + "exp_avg_sq") && !d.d.count(k + "step")) continue;  // no step taken yet
      const torch::Tensor& p = groups[g].params()[i];
      auto st = std::make_unique<torch::optim::AdamParamState>();
      st->exp_avg(d.entry(k + "exp_avg", p.sizes(), kOtherConfig).to(p.device(), p.scalar_type()).clone());
      st->exp_avg_sq(d.entry(k + "exp_avg_sq", p.sizes(), kOtherConfig).to(p.device(), p.scalar_type()).clone());
      if ((st->exp_avg_sq() < 0).any().item<bool>()) input_error(path, k + "exp_avg_sq holds negative values");
      st->step(d.count(k + "step"));
      adam.emplace_back(p, std::move(st));
    }
  double baseline = std::numeric_limits<double>::quiet_NaN();
  if (d.d.count("baseline.inv_depth_per_m")) {
    baseline = d.scalar("baseline.inv_depth_per_m");
    if (!(baseline > 0)) input_error(path, "baseline.inv_depth_per_m must be > 0");
  }
  const int64_t next = d.count("step");
  size_t live_found = 0;
  for (const auto& [name, dst] : s.live) live_found += d.d.count(name);
  if (live_found != 0 && live_found != s.live.size())
    input_error(path, "holds " + std::to_string(live_found) + " of the " + std::to_string(s.live.size()) +
                          " live.* entries of weight averaging (train.ema_decay): damaged?");
  if (live_found != 0)
    for (const auto& [name, dst] : s.live) copies.emplace_back(dst, d.entry(name, dst.sizes(), kOtherConfig));
  s.live_read = live_found != 0;
  // The illuminant reader's moments: all three entries or none.
  model::IlluminantMoments illuminant;
  const std::vector<std::string> il_names{"illuminant.mean", "illuminant.second", "illuminant.intensity_range"};
  size_t il_found = 0;
  for (const auto& n : il_names) il_found += d.d.count(n);
  if (il_found != 0 && il_found != il_names.size())
    input_error(path, "holds " + std::to_string(il_found) + " of the 3 illuminant.* entries (the illuminant reader's moments): damaged?");
  if (il_found != 0) {
    const torch::Tensor raw = dict_get(d.d, "illuminant.mean", path);
    const int64_t K = raw.dim() == 2 ? raw.size(0) : 0, L = s.net->options().bands;
    if (K < 1) input_error(path, "illuminant.mean must be [K, L] with K >= 1, is " + c10::str(raw.sizes()));
    const char* hint = "a checkpoint of another config? L = optics.wavelengths_nm";
    illuminant.mean = d.entry("illuminant.mean", {K, L}, hint).to(torch::kFloat64).clone();
    illuminant.second = d.entry("illuminant.second", {K, L, L}, hint).to(torch::kFloat64).clone();
    const torch::Tensor range = d.entry("illuminant.intensity_range", {2}, "two numbers: min, max").to(torch::kFloat64);
    illuminant.intensity_min = range[0].item<double>(), illuminant.intensity_max = range[1].item<double>();
    if (!(illuminant.intensity_min > 0 && illuminant.intensity_max >= illuminant.intensity_min))
      input_error(path, "illuminant.intensity_range must satisfy 0 < min <= max");
  }
  // All checked: replace the state.
  apply(copies);
  auto& state = s.adam.state();
  state.clear();
  for (auto& [p, st] : adam) state[c10::guts::to_string(p.unsafeGetTensorImpl())] = std::move(st);
  if (std::isfinite(baseline)) s.baseline_inv_depth = baseline;
  if (il_found != 0) s.illuminant = illuminant;
  return next;
}

void read_network_weights(const std::string& path, model::HsdNet& net) {
  const CheckedDict d{load_tensor_dict(path), path};
  torch::NoGradGuard no_grad;
  Copies copies;
  add_network(d, net, copies, "train.init_checkpoint must come from a config with the same network");
  apply(copies);
}

}  // namespace hsd::train
