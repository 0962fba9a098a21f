// Profiling a training step (Trainer::set_profile, hsd_bench train --profile):
// wall time per phase, and a PSF provider that cuts the graph at the PSFs so
// the backward pass can be timed in parts (network, sensor, PSF) by the same
// chain rule, with the same gradients.
#pragma once
#include <chrono>
#include <utility>
#include <vector>

#include <torch/torch.h>

#include "optics/psf.h"
#include "optics/sensor.h"
#include "train/step_stats.h"

namespace hsd::train {

// Adds the seconds since the previous lap to a phase of *profile; does nothing
// without a profile.
class PhaseTimer {
 public:
  explicit PhaseTimer(StepProfile* profile) : profile_(profile), tic_(Clock::now()) {}
  void lap(double StepProfile::*phase);

 private:
  using Clock = std::chrono::steady_clock;
  StepProfile* profile_;
  Clock::time_point tic_;
};

// A PSF provider's calls, timed, with each output replaced by a leaf copy
// (a cut) so the PSFs' backward can run on its own.
class PsfCuts {
 public:
  // Wraps `base` (or sim.compute when base is empty); the result keeps
  // references to this object and to sim.
  optics::PsfProvider wrap(optics::PsfProvider base, const optics::PsfSimulator& sim);
  double seconds() const { return seconds_; }  // in the wrapped calls so far
  // Backpropagates the cuts' gradients into the height map: one call, since
  // the stacks share the DOE's graph.
  void backward();

 private:
  double seconds_ = 0;
  std::vector<std::pair<torch::Tensor, torch::Tensor>> cuts_;  // each PSF stack and its cut copy
};

}  // namespace hsd::train
