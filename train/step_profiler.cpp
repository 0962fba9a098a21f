#include "train/step_profiler.h"

namespace hsd::train {

void PhaseTimer::lap(double StepProfile::*phase) {
  if (!profile_) return;
  const auto now = Clock::now();
  profile_->*phase += std::chrono::duration<double>(now - tic_).count();
  tic_ = now;
}

optics::PsfProvider PsfCuts::wrap(optics::PsfProvider base, const optics::PsfSimulator& sim) {
  return [this, base = std::move(base), &sim](const torch::Tensor& h, const std::vector<int64_t>& layers,
                                              const std::vector<int64_t>& bands) {
    const auto t = std::chrono::steady_clock::now();
    const torch::Tensor out = base ? base(h, layers, bands) : sim.compute(h, layers, {}, bands).psf;
    seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    cuts_.emplace_back(out, out.requires_grad() ? out.detach().requires_grad_() : out);
    return cuts_.back().second;
  };
}

void PsfCuts::backward() {
  std::vector<torch::Tensor> outs, grads;
  for (const auto& [out, cut] : cuts_)
    if (cut.requires_grad() && cut.grad().defined()) outs.push_back(out), grads.push_back(cut.grad());
  if (!outs.empty()) torch::autograd::backward(outs, grads);
}

}  // namespace hsd::train
