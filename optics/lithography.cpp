#include "optics/lithography.h"

#include <algorithm>
#include <cmath>
#include <map>

#include <torch/torch.h>

namespace hsd::optics {

LevelMap quantize_to_levels(const torch::Tensor& height_m, double max_height_m, int64_t levels) {
  LevelMap q;
  q.levels = levels;
  q.step_m = max_height_m / double(levels);
  const torch::Tensor h = torch::remainder(height_m.detach().to(torch::kCPU, torch::kFloat64), max_height_m);
  q.level = torch::remainder(torch::round(h / q.step_m), double(levels)).to(torch::kInt64);
  return q;
}

torch::Tensor level_heights(const LevelMap& q) { return q.level.to(torch::kFloat64) * q.step_m; }

int64_t level_mask_count(int64_t levels) {
  int64_t m = 0;
  while ((int64_t(1) << m) < levels) ++m;
  return m;
}

torch::Tensor level_masks(const LevelMap& q) {
  const int64_t m = level_mask_count(q.levels);
  std::vector<torch::Tensor> masks;
  for (int64_t k = 0; k < m; ++k) masks.push_back(torch::bitwise_and(q.level, int64_t(1) << k).ne(0));
  return torch::stack(masks);
}

torch::Tensor height_from_masks(const torch::Tensor& masks, double step_m) {
  // The level index first (integers), then its height: the same rounding as level_heights.
  torch::Tensor q = torch::zeros({masks.size(1), masks.size(2)}, torch::kInt64);
  for (int64_t k = 0; k < masks.size(0); ++k) q = q + masks[k].to(torch::kInt64) * (int64_t(1) << k);
  return q.to(torch::kFloat64) * step_m;
}

double quantisation_rms_m(const torch::Tensor& height_m, const LevelMap& q, double max_height_m) {
  const torch::Tensor h = height_m.detach().to(torch::kCPU, torch::kFloat64);
  const torch::Tensor d = torch::remainder(level_heights(q) - h + 0.5 * max_height_m, max_height_m) - 0.5 * max_height_m;
  return d.pow(2).mean().sqrt().item<double>();
}

std::vector<int64_t> level_histogram(const LevelMap& q) {
  const torch::Tensor c = torch::bincount(q.level.flatten(), {}, q.levels);
  std::vector<int64_t> out(size_t(q.levels));
  for (int64_t k = 0; k < q.levels; ++k) out[size_t(k)] = c[k].item<int64_t>();
  return out;
}

namespace {
// Runs of equal values along the last axis of a [R, C] uint8 accessor-backed
// array; interior runs only (not touching column 0 or C−1).
template <typename F>
void for_each_interior_run(const uint8_t* a, int64_t rows, int64_t cols, int64_t row_stride, int64_t col_stride, F&& f) {
  for (int64_t r = 0; r < rows; ++r) {
    int64_t start = 0;
    for (int64_t c = 1; c <= cols; ++c) {
      if (c < cols && a[r * row_stride + c * col_stride] == a[r * row_stride + start * col_stride]) continue;
      if (start > 0 && c < cols) f(a[r * row_stride + start * col_stride] != 0, c - start);
      start = c;
    }
  }
}
}  // namespace

MaskFeatures mask_features(const torch::Tensor& mask, double min_feature_cells) {
  const torch::Tensor m = mask.to(torch::kCPU, torch::kUInt8).contiguous();
  const int64_t N = m.size(0), M = m.size(1);
  const uint8_t* a = m.data_ptr<uint8_t>();
  MaskFeatures f;
  auto take = [&](bool line, int64_t len) {
    int64_t& best = line ? f.min_line_cells : f.min_space_cells;
    if (best == 0 || len < best) best = len;
    if (double(len) < min_feature_cells) ++(line ? f.lines_below : f.spaces_below);
  };
  for_each_interior_run(a, N, M, M, 1, take);  // along rows
  for_each_interior_run(a, M, N, 1, M, take);  // along columns
  f.covered_fraction = m.to(torch::kFloat64).mean().item<double>();
  return f;
}

std::vector<CellRect> mask_rectangles(const torch::Tensor& mask) {
  const torch::Tensor m = mask.to(torch::kCPU, torch::kUInt8).contiguous();
  const int64_t N = m.size(0), M = m.size(1);
  const uint8_t* a = m.data_ptr<uint8_t>();
  std::vector<CellRect> done;
  std::map<std::pair<int64_t, int64_t>, CellRect> open;  // (col0, cols) -> growing rectangle
  for (int64_t r = 0; r <= N; ++r) {
    std::map<std::pair<int64_t, int64_t>, CellRect> next;
    if (r < N) {
      for (int64_t c = 0; c < M;) {
        if (!a[r * M + c]) { ++c; continue; }
        int64_t e = c;
        while (e < M && a[r * M + e]) ++e;
        const std::pair<int64_t, int64_t> key{c, e - c};
        auto it = open.find(key);
        if (it != open.end()) {
          CellRect g = it->second;
          ++g.rows;
          next[key] = g;
          open.erase(it);
        } else {
          next[key] = CellRect{r, c, 1, e - c};
        }
        c = e;
      }
    }
    for (auto& [k, g] : open) done.push_back(g);
    open.swap(next);
  }
  std::sort(done.begin(), done.end(), [](const CellRect& x, const CellRect& y) {
    return x.row0 != y.row0 ? x.row0 < y.row0 : x.col0 < y.col0;
  });
  return done;
}

}  // namespace hsd::optics
