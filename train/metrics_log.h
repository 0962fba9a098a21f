// Training's metrics.csv (docs/formats.md: step, wall_s, train_loss,
// val_loss, then hsd's additions) and its three plots: curves.png (training
// and validation loss), val_psnr.png and val_depth.png (the model beside its
// baselines on the same patches; a curve that does not leave its baseline has
// learned nothing). Rows are kept in memory, cells reached by column name, and
// the files rewritten atomically after each row.
#pragma once
#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "train/step_stats.h"

namespace hsd::train {

class MetricsLog {
 public:
  // metrics.csv's columns, in order.
  static const std::vector<std::string>& columns();

  // A log that writes to out_dir (nothing when out_dir is empty: ranks other than 0).
  explicit MetricsLog(std::string out_dir) : out_dir_(std::move(out_dir)) {}
  // Continue out_dir/metrics.csv of an interrupted run: its rows up to step
  // `start` (rows of an earlier hsd, with fewer columns, padded). InputError
  // naming the file for a row that is not hsd_train's. Returns the last kept
  // row's wall time [s].
  double resume(int64_t start);
  // The same check without keeping the rows (hsd_train --resume, before the data).
  static void check_resumable(const std::string& csv, int64_t start);

  // A new row for step `step` after wall_s seconds; then the training and
  // validation cells of that row.
  void add_row(int64_t step, double wall_s);
  void set_train(const StepStats& s);
  void set_val(const ValStats& v);
  // metrics.csv and the plots, atomically.
  void write() const;

  size_t rows() const { return rows_.size(); }

 private:
  static std::vector<std::vector<std::string>> read_rows(const std::string& csv, int64_t start, double* wall_s);
  void set(const char* column, const std::string& cell);
  // One cell of the last row: column, printf format of the value, the value
  // (left empty when only_finite and the value is not finite).
  struct Cell {
    const char* column;
    const char* format;
    double value;
    bool only_finite = false;
  };
  void set_cells(std::initializer_list<Cell> cells);
  std::string out_dir_;
  std::vector<std::vector<std::string>> rows_;  // cells; empty where not measured
};

}  // namespace hsd::train
