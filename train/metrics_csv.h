// Reading training's metrics.csv (docs/formats.md: a header row with step,
// wall_s, train_loss, val_loss, ...; MetricsLog::columns lists them all):
// rows of cells, empty where not measured, reached by column name.
#pragma once
#include <string>
#include <vector>

namespace hsd::train {

// Cells of one CSV line (no quoting; hsd's metrics have none).
std::vector<std::string> split_csv_line(const std::string& line);
// The data rows of a CSV file (the header skipped); empty if the file is missing.
std::vector<std::vector<std::string>> read_csv_rows(const std::string& path);

// A CSV file with its header: cells by column name.
struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  // The index of column `name`; header.size() when there is none.
  size_t column(const std::string& name) const;
  bool has(const std::string& name) const { return column(name) < header.size(); }
  // Row r's cell in column `name`: empty when the row is short or the column absent.
  std::string cell(size_t r, const std::string& name) const;
  // Row r's cell as a number: NaN when empty or not a number.
  double number(size_t r, const std::string& name) const;
};
// Empty (no header, no rows) if the file is missing.
CsvTable read_csv_table(const std::string& path);

}  // namespace hsd::train
