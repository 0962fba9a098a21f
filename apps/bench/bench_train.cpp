// hsd_bench train: seconds per training step (PSF + sensor simulation +
// network forward/backward + Adam on the DOE and the network) and peak memory,
// for the config (default: the paper's) on --batch patches of --patch pixels;
// the network alone is timed in the same run for reference.
#include <cstdio>

#include <torch/torch.h>

#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/error.h"
#include "common/log.h"
#include "train/trainer.h"

namespace hsd::bench {

int bench_train(Config cfg, const AppArgs& args, BenchOutput& out) {
  const int64_t patch = args.integer("--patch", 256), batch = args.integer("--batch", 1);
  const int repeats = int(args.integer("--repeats", 3));
  if (patch < 16 || patch > 2048) input_error("--patch", "must be in [16, 2048]");
  if (batch < 1 || batch > 64) input_error("--batch", "must be in [1, 64]");
  cfg.train.batch_size = batch;
  const int64_t L = int64_t(cfg.optics.wavelengths_nm.size()), Z = int64_t(cfg.optics.depths_m.size());
  const double rss_start = current_rss_mib();
  train::Trainer t(cfg);
  const train::Batch b = striped_batch(cfg, batch, patch);
  int64_t k = 0;
  log::info("training steps ...");
  const double t_step = median_seconds([&] { t.step(b, k++); }, repeats);
  const double peak = peak_rss_during([&] { t.step(b, k++); });
  log::info("network alone ...");
  const torch::Tensor x = torch::rand({batch, 3, patch, patch});
  const double t_net = median_seconds([&] {
    const auto o = t.net()->forward(x);
    (o.hs.mean() + o.depth_m.mean()).backward();
  }, repeats);
  out.json = Json{{"bench", "train"}, {"threads", torch::get_num_threads()}, {"patch", patch}, {"batch", batch},
                  {"bands", L}, {"depths", Z}, {"psf", cfg.optics.psf_size}, {"pupil", cfg.optics.doe_samples},
                  {"base_width", cfg.model.base_width}, {"levels", cfg.model.levels}, {"seconds_per_step", t_step},
                  {"seconds_network_fwd_bwd", t_net}, {"peak_rss_mib", peak}, {"rss_at_start_mib", rss_start}};
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "training step: %lld x %lld px patch(es), batch %lld, %lld bands, %lld depths, PSF %lld, pupil %lld, "
                "U-Net width %lld x %lld levels, threads %d\n"
                "step (PSF + sensor + network + Adam)  %7.3f s   peak RSS %.0f MiB\n"
                "network alone, forward+backward       %7.3f s\n",
                (long long)patch, (long long)patch, (long long)batch, (long long)L, (long long)Z,
                (long long)cfg.optics.psf_size, (long long)cfg.optics.doe_samples, (long long)cfg.model.base_width,
                (long long)cfg.model.levels, torch::get_num_threads(), t_step, peak, t_net);
  out.text = buf;
  return 0;
}

}  // namespace hsd::bench
