// Timing and memory measurement for hsd_bench.
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "common/config.h"
#include "train/trainer.h"

namespace hsd::bench {

// The training benchmarks' batch: `batch` patches of patch × patch px, random
// radiance (seeded by the config), depth in vertical stripes over every layer.
train::Batch striped_batch(const Config& cfg, int64_t batch, int64_t patch);

// A trainer built without data (the benchmarks') has no spectral prior; a
// network whose cube is a residual on the spectral Wiener cube
// (model.residual = "spectral_wiener") needs one before its first step. Sets
// the radiance moments of batch b [B, L, H, W] and the sensor's mean noise
// variance as that prior (train::training_spectral_prior, the batch as
// radiance scenes); does nothing for other networks. Timing only: the prior's
// values do not change the work a step does.
void give_batch_spectral_prior(train::Trainer& t, const Config& cfg, const train::Batch& b);

// The median of v (non-empty), and the wall seconds one call of f takes.
double median(std::vector<double> v);
double seconds(const std::function<void()>& f);

// Runs f `repeats` times (after one untimed warm-up if warmup) and returns the median seconds.
double median_seconds(const std::function<void()>& f, int repeats, bool warmup = true);

// Peak resident memory of this process since the last reset_peak_rss(), MiB
// (Linux VmHWM; reset through /proc/self/clear_refs).
void reset_peak_rss();
double peak_rss_mib();
double current_rss_mib();

// Runs f and returns the peak RSS (MiB) reached while it ran.
double peak_rss_during(const std::function<void()>& f);

}  // namespace hsd::bench
