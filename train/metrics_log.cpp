#include "train/metrics_log.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/text_format.h"
#include "train/metrics_csv.h"
#include "viz/plot.h"

namespace hsd::train {

namespace {

size_t column_index(const char* name) {
  const auto& c = MetricsLog::columns();
  const size_t i = size_t(std::find(c.begin(), c.end(), std::string(name)) - c.begin());
  if (i == c.size()) throw std::invalid_argument(std::string("metrics.csv has no column ") + name);
  return i;
}

double number(const std::vector<std::string>& row, const char* column) {
  const std::string& c = row[column_index(column)];
  return c.empty() ? std::nan("") : std::atof(c.c_str());
}

}  // namespace

const std::vector<std::string>& MetricsLog::columns() {
  static const std::vector<std::string> c{
      "step",     "wall_s",         "train_loss",       "val_loss",         "train_hs_l1",
      "train_depth_l1", "lr_net",   "lr_doe_m",         "val_hs_psnr_db",   "val_depth_rmse_m",
      "val_depth_mae_m", "val_baseline_hs_psnr_db", "val_baseline_depth_rmse_m", "val_depth_saturated",
      "val_baseline_wiener_hs_psnr_db"};
  return c;
}

std::vector<std::vector<std::string>> MetricsLog::read_rows(const std::string& csv, int64_t start, double* wall_s) {
  std::vector<std::vector<std::string>> rows;
  for (auto c : read_csv_rows(csv)) {
    // Rows up to the checkpoint's step were written before it; a row of an
    // earlier hsd (fewer columns) is padded with empty cells.
    char* end = nullptr;
    const long long row_step = c.size() > 1 ? std::strtoll(c[0].c_str(), &end, 10) : -1;
    if (c.size() < 2 || end == c[0].c_str() || *end != '\0' || c.size() > columns().size())
      input_error(csv, "a row that is not one of hsd_train's (\"" + (c.empty() ? std::string() : c[0]) + "...\"); remove the file to resume without it");
    if (row_step > start) continue;
    c.resize(columns().size());
    rows.push_back(c);
    if (wall_s) *wall_s = std::atof(c[1].c_str());
  }
  return rows;
}

double MetricsLog::resume(int64_t start) {
  double wall = 0.0;
  if (!out_dir_.empty()) rows_ = read_rows(out_dir_ + "/metrics.csv", start, &wall);
  return wall;
}

void MetricsLog::check_resumable(const std::string& csv, int64_t start) { read_rows(csv, start, nullptr); }

void MetricsLog::add_row(int64_t step, double wall_s) {
  rows_.emplace_back(columns().size());
  set("step", std::to_string(step));
  set("wall_s", format("%.3f", wall_s));
}

void MetricsLog::set(const char* column, const std::string& cell) { rows_.back()[column_index(column)] = cell; }

void MetricsLog::set_cells(std::initializer_list<Cell> cells) {
  for (const Cell& c : cells)
    if (!c.only_finite || std::isfinite(c.value)) set(c.column, format(c.format, c.value));
}

void MetricsLog::set_train(const StepStats& s) {
  set_cells({{"train_loss", "%.6g", s.loss},
             {"train_hs_l1", "%.6g", s.hs},
             {"train_depth_l1", "%.6g", s.depth},
             {"lr_net", "%.4g", s.lr_net},
             {"lr_doe_m", "%.4g", s.lr_doe}});
}

void MetricsLog::set_val(const ValStats& v) {
  set_cells({{"val_loss", "%.6g", v.loss},
             {"val_hs_psnr_db", "%.4f", v.hs_psnr_db},
             {"val_depth_rmse_m", "%.5f", v.depth_rmse_m},
             {"val_depth_mae_m", "%.5f", v.depth_mae_m},
             {"val_baseline_hs_psnr_db", "%.4f", v.baseline_hs_psnr_db},
             {"val_baseline_depth_rmse_m", "%.5f", v.baseline_depth_rmse_m},
             {"val_depth_saturated", "%.4f", v.depth_saturated},
             {"val_baseline_wiener_hs_psnr_db", "%.4f", v.baseline_wiener_hs_psnr_db, true}});  // NaN without a pre-inversion
}

void MetricsLog::write() const {
  if (out_dir_.empty()) return;
  const auto& cols = columns();
  std::string text;
  for (size_t i = 0; i < cols.size(); ++i) text += (i ? "," : "") + cols[i];
  text += "\n";
  std::vector<double> xs, tr, vx, vl, psnr, base_psnr, rmse, base_rmse, wx, wiener_psnr;
  for (const auto& c : rows_) {
    for (size_t i = 0; i < c.size(); ++i) text += (i ? "," : "") + c[i];
    text += "\n";
    xs.push_back(number(c, "step"));
    tr.push_back(number(c, "train_loss"));
    if (c[column_index("val_loss")].empty()) continue;
    vx.push_back(number(c, "step"));
    vl.push_back(number(c, "val_loss"));
    psnr.push_back(number(c, "val_hs_psnr_db"));
    base_psnr.push_back(number(c, "val_baseline_hs_psnr_db"));
    rmse.push_back(number(c, "val_depth_rmse_m"));
    base_rmse.push_back(number(c, "val_baseline_depth_rmse_m"));
    if (!c[column_index("val_baseline_wiener_hs_psnr_db")].empty())
      wx.push_back(vx.back()), wiener_psnr.push_back(number(c, "val_baseline_wiener_hs_psnr_db"));
  }
  write_text_file(out_dir_ + "/metrics.csv", text);
  viz::write_line_plot(out_dir_ + "/curves.png", "loss (L1 cube + weighted depth terms)", "step",
                       {{"train", xs, tr, {200, 120, 30}}, {"validation", vx, vl, {30, 30, 200}}}, true);
  if (vx.empty()) return;
  std::vector<viz::Series> hs_lines{{"model", vx, psnr, {30, 140, 30}}, {"upsampling alone", vx, base_psnr, {150, 150, 150}}};
  if (!wx.empty()) hs_lines.push_back({"Wiener + upsampling", wx, wiener_psnr, {90, 90, 200}});
  viz::write_line_plot(out_dir_ + "/val_psnr.png", "validation hyperspectral PSNR [dB]", "step", hs_lines, false);
  viz::write_line_plot(out_dir_ + "/val_depth.png", "validation depth RMSE [m]", "step",
                       {{"model", vx, rmse, {200, 60, 30}}, {"constant depth", vx, base_rmse, {150, 150, 150}}}, false);
}

}  // namespace hsd::train
