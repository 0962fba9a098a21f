// Reconstruction of large frames in overlapping tiles with bounded memory: each
// tile of `tile` pixels is run with `overlap` pixels of context on every side
// and blended into the output with linear ramps across the overlaps (weights
// sum to one), so seams vanish once the overlap exceeds the network's
// receptive field. Memory: the outputs plus one tile with its context.
#pragma once
#include <functional>
#include <utility>

#include <torch/types.h>

namespace hsd::model {

// f: [1, 3, h, w] -> (hs [1, L, h, w], depth [1, 1, h, w]). image [3, H, W].
// Returns (hs [L, H, W], depth [1, H, W]). on_tile(done, total) reports progress.
std::pair<torch::Tensor, torch::Tensor> tiled_reconstruct(
    const std::function<std::pair<torch::Tensor, torch::Tensor>(const torch::Tensor&)>& f, const torch::Tensor& image,
    int64_t tile, int64_t overlap, const std::function<void(int64_t, int64_t)>& on_tile = {});

}  // namespace hsd::model
