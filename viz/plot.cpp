#include "viz/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/atomic_file.h"
#include "common/error.h"

namespace hsd::viz {

void write_line_plot(const std::string& path, const std::string& title, const std::string& x_label,
                     const std::vector<Series>& series, bool log_y) {
  const int W = 680, H = 400, left = 70, right = 190, top = 30, bottom = 45;
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  auto tr = [&](double y) { return log_y ? std::log10(y) : y; };
  for (const auto& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i]) || (log_y && s.y[i] <= 0)) continue;
      x0 = std::min(x0, s.x[i]), x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, tr(s.y[i])), y1 = std::max(y1, tr(s.y[i]));
    }
  if (x0 > x1) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (x1 - x0 < 1e-12) x1 = x0 + 1;
  if (y1 - y0 < 1e-12) y0 -= 0.5, y1 += 0.5;
  const double pad = 0.05 * (y1 - y0);
  y0 -= pad, y1 += pad;
  auto px = [&](double x) { return left + int((x - x0) / (x1 - x0) * (W - left - right)); };
  auto py = [&](double y) { return H - bottom - int((y - y0) / (y1 - y0) * (H - top - bottom)); };
  cv::rectangle(img, cv::Point(left, top), cv::Point(W - right, H - bottom), cv::Scalar(0, 0, 0), 1);
  char buf[64];
  for (int k = 0; k <= 4; ++k) {  // y ticks
    const double v = y0 + (y1 - y0) * k / 4.0;
    std::snprintf(buf, sizeof buf, "%.3g", log_y ? std::pow(10.0, v) : v);
    cv::putText(img, buf, cv::Point(4, py(v) + 4), cv::FONT_HERSHEY_SIMPLEX, 0.38, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    cv::line(img, cv::Point(left, py(v)), cv::Point(W - right, py(v)), cv::Scalar(225, 225, 225), 1);
    const double xv = x0 + (x1 - x0) * k / 4.0;
    std::snprintf(buf, sizeof buf, "%.4g", xv);
    cv::putText(img, buf, cv::Point(px(xv) - 12, H - bottom + 16), cv::FONT_HERSHEY_SIMPLEX, 0.38, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  cv::putText(img, title, cv::Point(left, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  cv::putText(img, x_label, cv::Point((W - right + left) / 2 - 20, H - 8), cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  int legend_y = top + 14;
  for (const auto& s : series) {
    const cv::Scalar c(s.bgr[0], s.bgr[1], s.bgr[2]);
    std::vector<cv::Point> pts;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
      if (std::isfinite(s.y[i]) && (!log_y || s.y[i] > 0)) pts.emplace_back(px(s.x[i]), py(tr(s.y[i])));
    if (pts.size() == 1) cv::circle(img, pts[0], 3, c, -1);
    if (pts.size() > 1) cv::polylines(img, pts, false, c, 2, cv::LINE_AA);
    for (const auto& p : pts)
      if (pts.size() < 40) cv::circle(img, p, 2, c, -1);
    cv::line(img, cv::Point(W - right + 10, legend_y - 4), cv::Point(W - right + 30, legend_y - 4), c, 2);
    cv::putText(img, s.name, cv::Point(W - right + 35, legend_y), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    legend_y += 18;
  }
  std::vector<uchar> out;
  if (!cv::imencode(".png", img, out)) input_error(path, "PNG encoding failed");
  write_binary_file(path, std::vector<char>(out.begin(), out.end()));
}

std::vector<size_t> pareto_front(const std::vector<LabelledPoint>& points) {
  std::vector<size_t> order;
  for (size_t i = 0; i < points.size(); ++i)
    if (std::isfinite(points[i].x) && std::isfinite(points[i].y)) order.push_back(i);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return points[a].x != points[b].x ? points[a].x < points[b].x : points[a].y < points[b].y;
  });
  std::vector<size_t> front;
  double best = std::numeric_limits<double>::infinity();
  for (size_t i : order)
    if (points[i].y < best) {
      front.push_back(i);
      best = points[i].y;
    }
  return front;
}

void write_pareto_plot(const std::string& path, const std::string& title, const std::string& x_label,
                       const std::string& y_label, const std::vector<LabelledPoint>& points,
                       const std::string& highlight, double y_line) {
  const int W = 860, H = 520, left = 80, right = 30, top = 34, bottom = 50;
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (const auto& p : points)
    if (p.x > 0 && p.y > 0 && std::isfinite(p.x) && std::isfinite(p.y)) {
      x0 = std::min(x0, std::log10(p.x)), x1 = std::max(x1, std::log10(p.x));
      y0 = std::min(y0, std::log10(p.y)), y1 = std::max(y1, std::log10(p.y));
    }
  if (y_line > 0) y0 = std::min(y0, std::log10(y_line)), y1 = std::max(y1, std::log10(y_line));
  if (x0 > x1) x0 = -1, x1 = 0, y0 = -1, y1 = 0;
  x0 = std::floor(x0 * 4) / 4 - 0.05, x1 = std::ceil(x1 * 4) / 4 + 0.05;
  y0 = std::floor(y0) - 0.1, y1 = std::ceil(y1) + 0.1;
  auto px = [&](double x) { return left + int((std::log10(x) - x0) / (x1 - x0) * (W - left - right)); };
  auto py = [&](double y) { return H - bottom - int((std::log10(y) - y0) / (y1 - y0) * (H - top - bottom)); };
  const cv::Scalar black(0, 0, 0), grey(225, 225, 225);
  cv::rectangle(img, cv::Point(left, top), cv::Point(W - right, H - bottom), black, 1);
  char buf[64];
  for (int e = int(std::ceil(y0)); e <= int(std::floor(y1)); ++e) {  // decades of y
    const double v = std::pow(10.0, e);
    cv::line(img, cv::Point(left, py(v)), cv::Point(W - right, py(v)), grey, 1);
    std::snprintf(buf, sizeof buf, "1e%d", e);
    cv::putText(img, buf, cv::Point(8, py(v) + 4), cv::FONT_HERSHEY_SIMPLEX, 0.42, black, 1, cv::LINE_AA);
  }
  for (int k = 0; k <= 5; ++k) {  // x ticks, log spaced
    const double v = std::pow(10.0, x0 + (x1 - x0) * k / 5.0);
    std::snprintf(buf, sizeof buf, "%.3g", v);
    cv::line(img, cv::Point(px(v), top), cv::Point(px(v), H - bottom), grey, 1);
    cv::putText(img, buf, cv::Point(px(v) - 14, H - bottom + 18), cv::FONT_HERSHEY_SIMPLEX, 0.42, black, 1, cv::LINE_AA);
  }
  if (y_line > 0) {
    for (int x = left; x < W - right; x += 12)
      cv::line(img, cv::Point(x, py(y_line)), cv::Point(std::min(x + 6, W - right), py(y_line)), cv::Scalar(0, 0, 200), 1);
    std::snprintf(buf, sizeof buf, "%.3g", y_line);
    cv::putText(img, buf, cv::Point(W - right - 40, py(y_line) - 4), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 200), 1, cv::LINE_AA);
  }
  const auto front = pareto_front(points);
  std::vector<cv::Point> line;
  for (size_t i : front)
    if (points[i].x > 0 && points[i].y > 0) line.emplace_back(px(points[i].x), py(points[i].y));
  if (line.size() > 1) cv::polylines(img, line, false, cv::Scalar(60, 160, 60), 2, cv::LINE_AA);
  // Points first, then labels placed greedily where they overlap nothing placed
  // before (front and default first); a label with no free place is left out
  // (the CSV has every setting).
  std::vector<size_t> order;
  for (size_t i = 0; i < points.size(); ++i) order.push_back(i);
  auto rank = [&](size_t i) {
    return points[i].label == highlight ? 0 : std::find(front.begin(), front.end(), i) != front.end() ? 1 : 2;
  };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return rank(a) < rank(b); });
  std::vector<cv::Rect> taken;
  for (size_t i : order) {
    const auto& p = points[i];
    if (!(p.x > 0 && p.y > 0 && std::isfinite(p.x) && std::isfinite(p.y))) continue;
    taken.emplace_back(px(p.x) - 5, py(p.y) - 5, 11, 11);
  }
  for (size_t i : order) {
    const auto& p = points[i];
    if (!(p.x > 0 && p.y > 0 && std::isfinite(p.x) && std::isfinite(p.y))) continue;
    const bool hl = p.label == highlight;
    const cv::Scalar c = hl ? cv::Scalar(0, 0, 220) : rank(i) == 1 ? cv::Scalar(40, 140, 40) : cv::Scalar(150, 90, 30);
    cv::circle(img, cv::Point(px(p.x), py(p.y)), hl ? 6 : 4, c, -1, cv::LINE_AA);
    int base = 0;
    const cv::Size ts = cv::getTextSize(p.label, cv::FONT_HERSHEY_SIMPLEX, 0.38, 1, &base);
    const int X = px(p.x), Y = py(p.y);
    for (const auto& off : std::vector<cv::Point>{{8, -6}, {8, 14}, {-ts.width - 8, -6}, {-ts.width - 8, 14}, {8, -20},
                                                  {8, 28}, {-ts.width - 8, -20}, {-ts.width - 8, 28}, {-ts.width / 2, -14},
                                                  {-ts.width / 2, 24}, {8, -34}, {8, 42}}) {
      const cv::Rect box(X + off.x, Y + off.y - ts.height, ts.width, ts.height + base);
      if (box.x < left || box.x + box.width > W - right || box.y < top || box.y + box.height > H - bottom) continue;
      bool free = true;
      for (const auto& t : taken) free &= (box & t).area() == 0;
      if (!free) continue;
      cv::putText(img, p.label, cv::Point(X + off.x, Y + off.y), cv::FONT_HERSHEY_SIMPLEX, 0.38, c, 1, cv::LINE_AA);
      taken.push_back(box);
      break;
    }
  }
  cv::putText(img, title, cv::Point(left, 22), cv::FONT_HERSHEY_SIMPLEX, 0.5, black, 1, cv::LINE_AA);
  cv::putText(img, x_label, cv::Point((W + left) / 2 - 60, H - 12), cv::FONT_HERSHEY_SIMPLEX, 0.45, black, 1, cv::LINE_AA);
  cv::putText(img, y_label, cv::Point(left + 6, top + 16), cv::FONT_HERSHEY_SIMPLEX, 0.42, black, 1, cv::LINE_AA);
  cv::putText(img, "green line: Pareto front; red: default", cv::Point(W - right - 300, top + 16), cv::FONT_HERSHEY_SIMPLEX,
              0.4, black, 1, cv::LINE_AA);
  std::vector<uchar> out;
  if (!cv::imencode(".png", img, out)) input_error(path, "PNG encoding failed");
  write_binary_file(path, std::vector<char>(out.begin(), out.end()));
}

void write_montage(const std::vector<std::string>& files, int cols, double scale, const std::string& out) {
  std::vector<cv::Mat> rows, cells;
  int width = 0;
  for (size_t i = 0; i < files.size(); ++i) {
    cv::Mat m = cv::imread(files[i], cv::IMREAD_COLOR);
    if (scale != 1.0) cv::resize(m, m, cv::Size(), scale, scale, cv::INTER_NEAREST);
    cv::copyMakeBorder(m, m, 3, 3, 3, 3, cv::BORDER_CONSTANT, cv::Scalar(255, 255, 255));
    cells.push_back(m);
    if (int(cells.size()) == cols || i + 1 == files.size()) {
      int h = 0;
      for (auto& c : cells) h = std::max(h, c.rows);
      for (auto& c : cells)
        if (c.rows < h) cv::copyMakeBorder(c, c, 0, h - c.rows, 0, 0, cv::BORDER_CONSTANT, cv::Scalar(255, 255, 255));
      cv::Mat row;
      cv::hconcat(cells, row);
      width = std::max(width, row.cols);
      rows.push_back(row);
      cells.clear();
    }
  }
  for (auto& r : rows)
    if (r.cols < width) cv::copyMakeBorder(r, r, 0, 0, 0, width - r.cols, cv::BORDER_CONSTANT, cv::Scalar(255, 255, 255));
  cv::Mat all;
  cv::vconcat(rows, all);
  std::vector<uchar> png;
  cv::imencode(".png", all, png);
  write_binary_file(out, std::vector<char>(png.begin(), png.end()));
  for (const auto& f : files) std::filesystem::remove(f);
}

}  // namespace hsd::viz
