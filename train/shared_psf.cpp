#include "train/shared_psf.h"

#include <torch/csrc/autograd/custom_function.h>

namespace hsd::train {

namespace {

using torch::autograd::AutogradContext;
using torch::autograd::variable_list;

// local [l_r, Z, P, P] (this rank's bands) -> all bands [total, Z, P, P], with
// local placed at `offset`. Backward: the sum over ranks of the gradient for
// all bands, this rank's rows of it.
struct AssemblePsfs : torch::autograd::Function<AssemblePsfs> {
  static torch::Tensor forward(AutogradContext* ctx, torch::Tensor local, int64_t offset, int64_t total,
                               model::ReplicaGroup* group) {
    torch::Tensor full = torch::zeros({total, local.size(1), local.size(2), local.size(3)}, local.options());
    if (local.size(0) > 0) full.narrow(0, offset, local.size(0)).copy_(local);
    group->all_reduce_sum_(full, "the shared PSFs");
    ctx->saved_data["offset"] = offset;
    ctx->saved_data["count"] = local.size(0);
    ctx->saved_data["group"] = reinterpret_cast<int64_t>(group);
    return full;
  }
  static variable_list backward(AutogradContext* ctx, variable_list grads) {
    auto* group = reinterpret_cast<model::ReplicaGroup*>(ctx->saved_data["group"].toInt());
    torch::Tensor g = grads[0].contiguous().clone();
    group->all_reduce_sum_(g, "the shared PSFs' gradients");
    const int64_t offset = ctx->saved_data["offset"].toInt(), count = ctx->saved_data["count"].toInt();
    return {g.narrow(0, offset, count), torch::Tensor(), torch::Tensor(), torch::Tensor()};
  }
};

}  // namespace

optics::PsfProvider make_shared_psf_provider(const optics::PsfSimulator& sim, std::shared_ptr<model::ReplicaGroup> group) {
  return [&sim, group](const torch::Tensor& h, const std::vector<int64_t>& layers, const std::vector<int64_t>& bands) {
    const auto& spec = sim.spec();
    const int64_t L = int64_t(spec.wavelengths_m.size()), Z = int64_t(spec.depths_m.size()), P = spec.psf_size;
    // Which bands and layers any rank needs: one sum of indicators.
    torch::Tensor need = torch::zeros({L + Z}, torch::kFloat64);
    auto acc = need.accessor<double, 1>();
    for (int64_t b : bands) acc[b] = 1.0;
    for (int64_t z : layers) acc[L + z] = 1.0;
    group->all_reduce_sum_(need, "which PSFs the ranks need");
    std::vector<int64_t> ub, uz, band_pos(size_t(L), -1), layer_pos(size_t(Z), -1);
    for (int64_t b = 0; b < L; ++b)
      if (acc[b] > 0) band_pos[size_t(b)] = int64_t(ub.size()), ub.push_back(b);
    for (int64_t z = 0; z < Z; ++z)
      if (acc[L + z] > 0) layer_pos[size_t(z)] = int64_t(uz.size()), uz.push_back(z);
    const auto opts = torch::TensorOptions().dtype(spec.real_dtype).device(spec.device);
    const bool grad = h.requires_grad() && torch::GradMode::is_enabled();
    // Every rank sees the same union, so all return here together or none does.
    if (ub.empty() || uz.empty()) return torch::zeros({int64_t(bands.size()), int64_t(layers.size()), P, P}, opts);
    // This rank's contiguous share of the union's bands (possibly none).
    const int64_t W = group->world_size(), r = group->rank(), Lu = int64_t(ub.size());
    const int64_t lo = Lu * r / W, hi = Lu * (r + 1) / W;
    torch::Tensor local;
    if (hi > lo) {
      local = sim.compute(h, uz, {}, std::vector<int64_t>(ub.begin() + lo, ub.begin() + hi)).psf;
    } else {
      local = torch::zeros({0, int64_t(uz.size()), P, P}, opts);
      if (grad) local = local + (h.sum() * 0.0).to(spec.real_dtype);  // in the graph: its backward sum must run here too
    }
    const torch::Tensor full = AssemblePsfs::apply(local, lo, Lu, group.get());
    std::vector<int64_t> bi, zi;
    for (int64_t b : bands) bi.push_back(band_pos[size_t(b)]);
    for (int64_t z : layers) zi.push_back(layer_pos[size_t(z)]);
    const auto idx = torch::TensorOptions().dtype(torch::kInt64).device(spec.device);
    return full.index_select(0, torch::tensor(bi, idx)).index_select(1, torch::tensor(zi, idx));
  };
}

}  // namespace hsd::train
