// Reading training's metrics.csv (CONTRACT.md: header row with step, wall_s,
// train_loss, val_loss, ...): rows of cells, empty where not measured.
#pragma once
#include <string>
#include <vector>

namespace hsd::train {

// Cells of one CSV line (no quoting; hsd's metrics have none).
std::vector<std::string> split_csv_line(const std::string& line);
// The data rows of a CSV file (the header skipped); empty if the file is missing.
std::vector<std::vector<std::string>> read_csv_rows(const std::string& path);

}  // namespace hsd::train
