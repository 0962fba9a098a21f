// hsd_ablate: the paper's Table 2 protocol on our data: the same network, data
// and training budget with the DOE fixed to Fresnel, spiral and Fisher, against
// the end-to-end learned DOE initialised from Fisher; optional seeds. Runs
// hsd_fisher once, hsd_train and hsd_eval per (arm, seed) as subprocesses
// (each arm's folder is a normal training/evaluation output), then writes
// DIR/ablation.md, DIR/ablation.csv (mean ± spread over seeds) and
// DIR/error_vs_time.png (validation loss against wall-clock time, all arms).
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "train/metrics_csv.h"
#include "train/plot.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

const char* kUsage =
    "hsd_ablate --config FILE [--seeds 0,1,2] [--set key=VALUE ...] --out DIR\n"
    "  Trains the config's network with the DOE fixed to fresnel, spiral and fisher,\n"
    "  and learned end to end from fisher (same data and budget), evaluates each on\n"
    "  the test split, and writes DIR/ablation.md, DIR/ablation.csv and\n"
    "  DIR/error_vs_time.png. Each arm's training and evaluation output is in\n"
    "  DIR/<arm>_seed<k>/{run,eval}. Small budget: configs/ablation_quick.json;\n"
    "  the paper's: configs/ablation_paper.json.";

struct Arm {
  std::string name, init;
  bool freeze;
};

std::string quote(const std::string& s) { return "'" + s + "'"; }

void run_or_fail(const std::string& cmd, const std::string& what) {
  log::info("$ " + cmd);
  const int rc = std::system(cmd.c_str());
  if (rc != 0) throw NumericalError(what + " failed (exit status " + std::to_string(rc) + "); see its output above");
}

// (wall_s, val_loss) pairs of a metrics.csv.
std::vector<std::pair<double, double>> val_curve(const std::string& csv) {
  std::vector<std::pair<double, double>> out;
  for (const auto& c : train::read_csv_rows(csv))
    if (c.size() > 3 && !c[3].empty()) out.emplace_back(std::stod(c[1]), std::stod(c[3]));
  return out;
}

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);  // checked before anything runs
  std::vector<int64_t> seeds;
  {
    std::stringstream ss(args.option("--seeds", std::to_string(cfg.seed)));
    std::string tok;
    while (std::getline(ss, tok, ',')) {
      char* end = nullptr;
      const long long v = std::strtoll(tok.c_str(), &end, 10);
      if (tok.empty() || *end != '\0' || v < 0) input_error("--seeds", "expected comma-separated non-negative integers, got \"" + tok + "\"");
      seeds.push_back(v);
    }
  }
  make_dirs(args.out_dir);
  const std::string bin = fs::canonical("/proc/self/exe").parent_path().string();
  std::string common = " --config " + quote(args.config_path);
  for (const auto& o : args.overrides) common += " --set " + quote(o);
  // The Fisher DOE, once (it does not depend on the seed of the network).
  const std::string fisher_dir = args.out_dir + "/fisher";
  run_or_fail(bin + "/hsd_fisher" + common + " --out " + quote(fisher_dir), "hsd_fisher");
  const std::string fisher_file = fisher_dir + "/fisher_height.pt";
  const std::vector<Arm> arms{{"fresnel (fixed)", "fresnel", true},
                              {"spiral (fixed)", "spiral", true},
                              {"fisher (fixed)", "fisher", true},
                              {"end-to-end (from fisher)", "fisher", false}};
  const std::vector<std::string> keys{"hs_psnr_db", "hs_ssim", "lum_psnr_db", "lum_ssim", "depth_rmse_m", "depth_mae_m"};
  std::map<std::string, std::map<std::string, std::vector<double>>> results;  // arm -> metric -> per seed
  std::vector<train::Series> curves;
  const std::vector<std::array<int, 3>> colours{{40, 40, 200}, {40, 160, 40}, {200, 120, 30}, {20, 20, 20}};
  for (size_t a = 0; a < arms.size(); ++a) {
    for (int64_t seed : seeds) {
      std::string tag = arms[a].init + (arms[a].freeze ? "_fixed" : "_learned") + "_seed" + std::to_string(seed);
      const std::string dir = args.out_dir + "/" + tag;
      std::string sets = common + " --set seed=" + std::to_string(seed) + " --set optics.doe.init=" + arms[a].init +
                         " --set optics.doe.fisher_path=" + quote(fisher_file) +
                         " --set train.freeze_doe=" + (arms[a].freeze ? "true" : "false");
      run_or_fail(bin + "/hsd_train" + sets + " --out " + quote(dir + "/run"), "hsd_train (" + tag + ")");
      run_or_fail(bin + "/hsd_eval" + sets + " --checkpoint " + quote(dir + "/run/checkpoints/last.pt") + " --out " +
                      quote(dir + "/eval"),
                  "hsd_eval (" + tag + ")");
      const Json m = Json::parse(read_text_file(dir + "/eval/metrics.json"));
      for (const auto& k : keys) results[arms[a].name][k].push_back(m.at(k).get<double>());
      if (m.contains("colorchecker_reflectance_rmse"))
        results[arms[a].name]["colorchecker_reflectance_rmse"].push_back(m["colorchecker_reflectance_rmse"].get<double>());
      const auto c = val_curve(dir + "/run/metrics.csv");
      train::Series s{arms[a].name + (seeds.size() > 1 ? " s" + std::to_string(seed) : ""), {}, {}, colours[a]};
      for (const auto& [t, v] : c) s.x.push_back(t), s.y.push_back(v);
      curves.push_back(s);
    }
  }
  // Table: mean ± spread (standard deviation over seeds; 0 for one seed).
  auto stat = [](const std::vector<double>& v) {
    double m = 0, s = 0;
    for (double x : v) m += x / double(v.size());
    for (double x : v) s += (x - m) * (x - m);
    s = v.size() > 1 ? std::sqrt(s / double(v.size() - 1)) : 0.0;
    return std::make_pair(m, s);
  };
  std::vector<std::string> cols = keys;
  cols.push_back("colorchecker_reflectance_rmse");
  std::string csv = "arm,seeds";
  for (const auto& k : cols) csv += "," + k + "_mean," + k + "_std";
  csv += "\n";
  std::string md = "# DOE ablation (Baek et al. 2021, Table 2 protocol)\n\nSame network, data and budget; " +
                   std::to_string(seeds.size()) + " seed(s); mean ± standard deviation over seeds; test split.\n\n| arm |";
  for (const auto& k : cols) md += " " + k + " |";
  md += "\n|---|";
  for (size_t k = 0; k < cols.size(); ++k) md += "---|";
  md += "\n";
  char buf[128];
  for (const auto& arm : arms) {
    csv += "\"" + arm.name + "\"," + std::to_string(seeds.size());
    md += "| " + arm.name + " |";
    for (const auto& k : cols) {
      const auto& v = results[arm.name][k];
      if (v.empty()) {
        csv += ",,";
        md += " |";
        continue;
      }
      const auto [m, s] = stat(v);
      std::snprintf(buf, sizeof buf, ",%.6g,%.6g", m, s);
      csv += buf;
      std::snprintf(buf, sizeof buf, " %.4g ± %.2g |", m, s);
      md += buf;
    }
    csv += "\n";
    md += "\n";
  }
  const Json crlb = Json::parse(read_text_file(fisher_dir + "/crlb.json"));
  std::snprintf(buf, sizeof buf, "\nAggregated CRLB (hsd_fisher): fresnel %.4g, spiral %.4g, fisher %.4g.\n",
                crlb["fresnel"]["aggregate"].get<double>(), crlb["spiral"]["aggregate"].get<double>(),
                crlb["fisher"]["aggregate"].get<double>());
  md += buf;
  md += "\n![validation loss against wall-clock time](error_vs_time.png)\n";
  write_text_file(args.out_dir + "/ablation.csv", csv);
  write_text_file(args.out_dir + "/ablation.md", md);
  train::write_line_plot(args.out_dir + "/error_vs_time.png", "validation loss against wall-clock time", "seconds", curves, true);
  write_resolved_config(cfg, args.out_dir);
  std::printf("%s", md.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_ablate", kUsage, {"--seeds"}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
