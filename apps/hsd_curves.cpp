// hsd_curves: several training runs' metrics.csv columns in one plot each
// (e.g. float32 against bfloat16 training, or two seeds), with a table of the
// last values and their differences from the first run.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "train/metrics_csv.h"
#include "viz/plot.h"
#include "usage/hsd_curves.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

const char* kUsage = usage::kText;

std::vector<std::string> split_list(const std::string& s, const std::string& flag) {
  std::vector<std::string> out;
  std::stringstream in(s);
  for (std::string item; std::getline(in, item, ',');) {
    if (item.empty()) input_error(flag, "an empty entry in \"" + s + "\"");
    out.push_back(item);
  }
  if (out.empty()) input_error(flag, "expected a comma-separated list");
  return out;
}

struct Run {
  std::string name, csv;
  train::CsvTable table;
};

int run(const AppArgs& args) {
  const std::vector<std::string> dirs = split_list(args.option("--runs", ""), "--runs");
  const std::vector<std::string> columns =
      split_list(args.option("--columns", "val_loss,val_hs_psnr_db,val_depth_rmse_m"), "--columns");
  std::vector<Run> runs;
  for (const auto& d : dirs) {
    Run r;
    r.name = fs::path(d).lexically_normal().filename().string();
    if (r.name.empty() || r.name == ".") r.name = fs::path(d).lexically_normal().parent_path().filename().string();
    r.csv = (fs::path(d) / "metrics.csv").string();
    if (!fs::is_regular_file(r.csv)) input_error(r.csv, "no such file (--runs takes hsd_train output folders)");
    r.table = train::read_csv_table(r.csv);
    for (const auto& c : columns)
      if (!r.table.has(c)) input_error(r.csv, "has no column \"" + c + "\" (--columns)");
    runs.push_back(std::move(r));
  }
  check_output_paths({args.out_dir + "/curves.png", args.out_dir + "/curves.md"});
  make_dirs(args.out_dir);
  static const std::vector<std::array<int, 3>> colours{{200, 80, 30}, {30, 30, 220}, {40, 160, 40}, {150, 40, 150}, {0, 0, 0}};
  std::vector<std::string> pieces;
  std::string table = "| run |";
  for (const auto& c : columns) table += " " + c + " (last) |";
  table += "\n|---|";
  for (size_t i = 0; i < columns.size(); ++i) table += "---|";
  table += "\n";
  std::vector<std::vector<double>> last(runs.size(), std::vector<double>(columns.size(), std::nan("")));
  for (size_t ci = 0; ci < columns.size(); ++ci) {
    std::vector<viz::Series> series;
    for (size_t ri = 0; ri < runs.size(); ++ri) {
      const Run& r = runs[ri];
      viz::Series s{r.name, {}, {}, colours[ri % colours.size()]};
      for (size_t k = 0; k < r.table.rows.size(); ++k) {
        const double y = r.table.number(k, columns[ci]), x = r.table.number(k, "step");
        if (!std::isfinite(y) || !std::isfinite(x)) continue;
        s.x.push_back(x);
        s.y.push_back(y);
      }
      if (!s.y.empty()) last[ri][ci] = s.y.back();
      series.push_back(std::move(s));
    }
    const std::string f = args.out_dir + "/" + columns[ci] + ".png";
    viz::write_line_plot(f, columns[ci], "step", series, false);
    pieces.push_back(f);
  }
  for (size_t ri = 0; ri < runs.size(); ++ri) {
    table += "| " + runs[ri].name + " |";
    for (size_t ci = 0; ci < columns.size(); ++ci) {
      char buf[96];
      const double v = last[ri][ci], v0 = last[0][ci];
      if (ri == 0 || !std::isfinite(v0) || v0 == 0.0) std::snprintf(buf, sizeof buf, " %.5g |", v);
      else std::snprintf(buf, sizeof buf, " %.5g (%+.2f%%) |", v, 100.0 * (v - v0) / std::abs(v0));
      table += buf;
    }
    table += "\n";
  }
  // The montage replaces the pieces; keep them as separate files too.
  std::vector<std::string> copies;
  for (const auto& p : pieces) {
    const std::string c = p + ".part.png";
    fs::copy_file(p, c, fs::copy_options::overwrite_existing);
    copies.push_back(c);
  }
  viz::write_montage(copies, int(std::min<size_t>(3, copies.size())), 1.0, args.out_dir + "/curves.png");
  write_text_file(args.out_dir + "/curves.md", "# Runs compared (hsd_curves)\n\nIn brackets: the difference from the first run's last value.\n\n" + table);
  std::printf("%s", table.c_str());
  log::info("wrote " + args.out_dir + "/curves.png, curves.md and one PNG per column");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_curves", kUsage, {"--runs", "--columns"}, {}, false, true};
  return run_app(spec, argc, argv, run);
}
