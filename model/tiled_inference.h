// Reconstruction of large frames in overlapping tiles with bounded memory: each
// tile of `tile` pixels is run with `context` pixels of input on every side
// (at least `overlap`) and blended into the output with linear ramps across
// `overlap` pixels on each side of the tile edges (weights sum to one). Seams
// fall as the context grows (docs/benchmarks.md: seam error against context and time).
// Memory: the outputs plus one tile with its context.
#pragma once
#include <functional>
#include <utility>

#include <torch/types.h>

namespace hsd::model {

// f: [1, 3, h, w] -> (hs [1, L, h, w], depth [1, 1, h, w]). image [3, H, W].
// Returns (hs [L, H, W], depth [1, H, W]). on_tile(done, total) reports progress.
std::pair<torch::Tensor, torch::Tensor> tiled_reconstruct(
    const std::function<std::pair<torch::Tensor, torch::Tensor>(const torch::Tensor&)>& f, const torch::Tensor& image,
    int64_t tile, int64_t overlap, const std::function<void(int64_t, int64_t)>& on_tile = {}, int64_t context = -1);
// context < 0: 2·overlap.

}  // namespace hsd::model
