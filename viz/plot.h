// Line plots as PNG (OpenCV drawing): training curves against step.
#pragma once
#include <array>
#include <string>
#include <vector>

namespace hsd::viz {

struct Series {
  std::string name;
  std::vector<double> x, y;
  std::array<int, 3> bgr{0, 0, 0};
};

// One panel; log_y plots log10 of positive values. Written atomically.
void write_line_plot(const std::string& path, const std::string& title, const std::string& x_label,
                     const std::vector<Series>& series, bool log_y);

// Error against cost: one labelled point per (x, y) on log-log axes (x > 0,
// y > 0), the points on the Pareto front (no other point is both faster and
// more accurate) joined by a line, the point named `highlight` drawn larger,
// and a dashed horizontal line at y_line (if > 0). Written atomically.
struct LabelledPoint {
  std::string label;
  double x = 0, y = 0;
};
void write_pareto_plot(const std::string& path, const std::string& title, const std::string& x_label,
                       const std::string& y_label, const std::vector<LabelledPoint>& points,
                       const std::string& highlight, double y_line);

// Indices of the Pareto front of (x, y), both to be minimised, ascending in x.
std::vector<size_t> pareto_front(const std::vector<LabelledPoint>& points);

// Reads PNG files and lays them out in a grid (cols per row, white borders),
// enlarged by `scale`; writes `out` atomically and removes the pieces.
void write_montage(const std::vector<std::string>& files, int cols, double scale, const std::string& out);

}  // namespace hsd::viz
