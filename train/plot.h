// Line plots as PNG (OpenCV drawing): training curves against step.
#pragma once
#include <array>
#include <string>
#include <vector>

namespace hsd::train {

struct Series {
  std::string name;
  std::vector<double> x, y;
  std::array<int, 3> bgr{0, 0, 0};
};

// One panel; log_y plots log10 of positive values. Written atomically.
void write_line_plot(const std::string& path, const std::string& title, const std::string& x_label,
                     const std::vector<Series>& series, bool log_y);

// Reads PNG files and lays them out in a grid (cols per row, white borders),
// enlarged by `scale`; writes `out` atomically and removes the pieces.
void write_montage(const std::vector<std::string>& files, int cols, double scale, const std::string& out);

}  // namespace hsd::train
