#include "train/metrics_csv.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace hsd::train {

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> cells;
  std::stringstream ss(line);
  std::string cell;
  while (std::getline(ss, cell, ',')) cells.push_back(cell);
  if (!line.empty() && line.back() == ',') cells.push_back("");
  return cells;
}

std::vector<std::vector<std::string>> read_csv_rows(const std::string& path) { return read_csv_table(path).rows; }

CsvTable read_csv_table(const std::string& path) {
  CsvTable t;
  std::ifstream f(path);
  std::string line;
  if (!std::getline(f, line)) return t;
  t.header = split_csv_line(line);
  while (std::getline(f, line))
    if (!line.empty()) t.rows.push_back(split_csv_line(line));
  return t;
}

size_t CsvTable::column(const std::string& name) const {
  return size_t(std::find(header.begin(), header.end(), name) - header.begin());
}

std::string CsvTable::cell(size_t r, const std::string& name) const {
  const size_t c = column(name);
  return r < rows.size() && c < rows[r].size() ? rows[r][c] : std::string();
}

double CsvTable::number(size_t r, const std::string& name) const {
  const std::string s = cell(r, name);
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  return s.empty() || end == s.c_str() ? std::nan("") : v;
}

}  // namespace hsd::train
