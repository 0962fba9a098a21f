// hsd_bench train: seconds per training step (PSF + sensor simulation +
// network forward/backward + Adam on the DOE and the network) and peak memory,
// for the config (default: the paper's) on --batch patches of --patch pixels
// rendered with the config's scene margin around them, as training renders
// them. The network's two precisions (float32, bfloat16) side by side in the
// same run, the network alone for reference, and with --profile the step's
// phases (PSF, sensor, network, loss, the three parts of the backward pass,
// optimizer) of the config's precision.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <memory>
#include <numeric>
#include <vector>

#include <torch/torch.h>

#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/error.h"
#include "common/log.h"
#include "common/text_format.h"
#include "train/trainer.h"

namespace hsd::bench {

namespace {

struct Row {
  std::string precision;
  double step_s = 0, peak_mib = 0, net_s = 0;
};

// The row of one precision ("float32" or "bfloat16"; rows holds both).
const Row& row_of(const std::vector<Row>& rows, const std::string& precision) {
  return rows[0].precision == precision ? rows[0] : rows[1];
}

// The table of step and network times per precision (the config's first).
std::string steps_text(const Config& cfg, int64_t patch, int64_t margin, const std::vector<Row>& rows) {
  const int64_t L = int64_t(cfg.optics.wavelengths_nm.size()), Z = int64_t(cfg.optics.depths_m.size());
  std::string text = format(
      "training step: %lld x %lld px patch(es) rendered with %lld px of scene around them, batch %lld, "
      "%lld bands, %lld depths, PSF %lld, pupil %lld, U-Net width %lld x %lld levels, threads %d\n"
      "%s"
      "network precision     step (PSF + sensor + network + Adam)   network alone fwd+bwd   peak RSS\n",
      (long long)patch, (long long)patch, (long long)margin, (long long)cfg.train.batch_size, (long long)L, (long long)Z,
      (long long)cfg.optics.psf_size, (long long)cfg.optics.doe_samples, (long long)cfg.model.base_width,
      (long long)cfg.model.levels, torch::get_num_threads(),
      cfg.train.doe_every > 1 ? format("the DOE learns on one step in %lld (train.doe_every): the step is the mean over whole "
                                       "cycles, the others medians\n", (long long)cfg.train.doe_every).c_str()
                              : "");
  for (const Row& r : rows)
    text += format("%-9s%s %18.3f s %32.3f s %15s\n", r.precision.c_str(), &r == &rows[0] ? " (config)" : "         ",
                   r.step_s, r.net_s, r.peak_mib > 0 ? (std::to_string(int(r.peak_mib + 0.5)) + " MiB").c_str() : "");
  const Row &f32 = row_of(rows, "float32"), &bf16 = row_of(rows, "bfloat16");
  text += format("float32 / bfloat16: step %.2fx, network %.2fx\n", f32.step_s / bf16.step_s, f32.net_s / bf16.net_s);
  return text;
}

// --profile: the mean seconds of each phase of a step, as a table and in the JSON.
void append_profile(BenchOutput& out, const train::StepProfile& prof, const std::string& precision, double wall_s) {
  const double n = double(std::max<int64_t>(prof.steps, 1));
  const std::vector<std::pair<std::string, double>> phases{
      {"PSF forward", prof.psf_forward},         {"sensor image forward", prof.sensor_forward},
      {"network inputs forward (pre-inversion, spectral Wiener)", prof.inputs_forward},
      {"network forward", prof.network_forward}, {"loss (and its read-out)", prof.loss},
      {"network backward", prof.network_backward}, {"sensor image backward", prof.sensor_backward},
      {"PSF backward", prof.psf_backward},       {"gradient checks, clipping, Adam", prof.optimizer}};
  double sum = 0;
  for (const auto& p : phases) sum += p.second / n;
  out.text += format("\nphases of the step (%s, mean of %lld profiled steps):\n", precision.c_str(), (long long)prof.steps);
  Json jp = Json::object();
  for (const auto& [name, total] : phases) {
    out.text += format("  %-56s %8.3f s  %5.1f%%\n", name.c_str(), total / n, 100.0 * total / n / sum);
    jp[name] = total / n;
  }
  out.text += format("  %-56s %8.3f s\n", "sum", sum);
  out.json["profile_seconds"] = jp;
  out.json["profile_step_wall_seconds"] = wall_s;  // wall time per profiled step (the phases are disjoint parts of it)
}

}  // namespace

int bench_train(Config cfg, const AppArgs& args, BenchOutput& out) {
  const int64_t patch = args.integer("--patch", 256), batch = args.integer("--batch", 1);
  int repeats = int(args.integer("--repeats", 3));
  const bool profile = args.has("--profile");
  if (patch < 16 || patch > 2048) input_error("--patch", "must be in [16, 2048]");
  if (batch < 1 || batch > 64) input_error("--batch", "must be in [1, 64]");
  if (repeats < 1 || repeats > 1000) input_error("--repeats", "must be in [1, 1000]");
  // train.doe_every = N: steps alternate between the DOE's (one in N) and the
  // network's alone, so the step time is the mean over whole cycles of N.
  const int64_t every = cfg.train.doe_every;
  if (every > 1) repeats = int((repeats + every - 1) / every * every);
  cfg.train.batch_size = batch;
  cfg.data.patch_size_px = patch;
  const int64_t L = int64_t(cfg.optics.wavelengths_nm.size()), Z = int64_t(cfg.optics.depths_m.size());
  const int64_t margin = train::render_margin_px(cfg);
  const double rss_start = current_rss_mib();
  const train::Batch b = striped_batch(cfg, batch, patch + 2 * margin);
  // The config's precision first (its peak memory alone, its profile), then
  // both precisions' steps interleaved (A B A B ...), so that drift in the
  // machine's speed falls on both alike; medians.
  std::vector<Config> cfgs{cfg, cfg};
  std::vector<std::unique_ptr<train::Trainer>> trainers;
  trainers.push_back(std::make_unique<train::Trainer>(cfgs[0]));
  give_batch_spectral_prior(*trainers[0], cfgs[0], b);
  cfgs[1].train.precision = trainers[0]->precision().dtype == torch::kBFloat16 ? TrainPrecision::float32 : TrainPrecision::bfloat16;
  std::vector<Row> rows(2);
  std::vector<int64_t> k(2, 0);
  log::info("peak memory of a step (" + std::string(trainers[0]->precision().dtype == torch::kBFloat16 ? "bfloat16" : "float32") + ") ...");
  trainers[0]->step(b, k[0]++);  // warm-up
  rows[0].peak_mib = peak_rss_during([&] {  // over a whole cycle of train.doe_every steps (one moves the DOE)
    for (int64_t i = 0; i < every; ++i) trainers[0]->step(b, k[0]++);
  });
  trainers.push_back(std::make_unique<train::Trainer>(cfgs[1]));
  give_batch_spectral_prior(*trainers[1], cfgs[1], b);
  trainers[1]->step(b, k[1]++);
  std::vector<std::vector<double>> t_step(2), t_net(2);
  const torch::Tensor x = torch::rand({batch, 3, patch, patch});
  log::info("training steps and the network alone, float32 and bfloat16 interleaved ...");
  for (int i = 0; i < repeats; ++i)
    for (size_t r = 0; r < 2; ++r) {
      train::Trainer& t = *trainers[r];
      t_step[r].push_back(seconds([&] { t.step(b, k[r]++); }));
      t_net[r].push_back(seconds([&] {
        const auto o = t.net()->forward(x);
        (o.hs.mean() + o.depth_m.mean()).backward();
      }));
    }
  for (size_t r = 0; r < 2; ++r) {
    rows[r].precision = trainers[r]->precision().dtype == torch::kBFloat16 ? "bfloat16" : "float32";
    rows[r].step_s = every > 1 ? std::accumulate(t_step[r].begin(), t_step[r].end(), 0.0) / double(t_step[r].size())
                               : median(t_step[r]);
    rows[r].net_s = median(t_net[r]);
  }
  train::StepProfile prof;
  double profiled_wall_s = 0;  // wall time per profiled step (the phases are disjoint parts of it)
  if (profile) {
    log::info("profiled steps (" + rows[0].precision + ") ...");
    trainers[0]->set_profile(&prof);
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < repeats; ++i) trainers[0]->step(b, k[0]++);
    profiled_wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / repeats;
    trainers[0]->set_profile(nullptr);
  }
  const Row &f32 = row_of(rows, "float32"), &bf16 = row_of(rows, "bfloat16");

  out.json = Json{{"bench", "train"}, {"threads", torch::get_num_threads()}, {"patch", patch}, {"margin", margin},
                  {"batch", batch}, {"bands", L}, {"depths", Z}, {"psf", cfg.optics.psf_size},
                  {"pupil", cfg.optics.doe_samples}, {"base_width", cfg.model.base_width}, {"levels", cfg.model.levels},
                  {"precision", rows[0].precision}, {"seconds_per_step", rows[0].step_s},
                  {"seconds_network_fwd_bwd", rows[0].net_s}, {"peak_rss_mib", rows[0].peak_mib},
                  {"rss_at_start_mib", rss_start}, {"seconds_per_step_float32", f32.step_s},
                  {"seconds_per_step_bfloat16", bf16.step_s}, {"seconds_network_fwd_bwd_float32", f32.net_s},
                  {"seconds_network_fwd_bwd_bfloat16", bf16.net_s}};
  out.text = steps_text(cfg, patch, margin, rows);
  if (profile) append_profile(out, prof, rows[0].precision, profiled_wall_s);
  return 0;
}

}  // namespace hsd::bench
