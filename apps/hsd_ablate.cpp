// hsd_ablate: the paper's Table 2 protocol on our data: the same network, data
// and training budget with the DOE fixed to Fresnel, spiral and Fisher, against
// the end-to-end learned DOE initialised from Fisher, and the all-in-focus
// control (no optical cue: what the network gets from scene context alone);
// optional seeds. Runs hsd_fisher once, hsd_train and hsd_eval per (arm, seed)
// as subprocesses started from argument vectors, without a shell (each arm's
// folder is a normal training/evaluation output), then writes DIR/ablation.md
// (mean ± standard deviation over seeds beside the baselines, and pairwise
// differences marked where they exceed two standard errors), DIR/ablation.csv
// and DIR/error_vs_time.png (validation loss against wall-clock time, all arms).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/sample_stats.h"
#include "common/subprocess.h"
#include "common/text_format.h"
#include "train/metrics_csv.h"
#include "viz/plot.h"
#include "usage/hsd_ablate.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

const char* kUsage = usage::kText;

struct Arm {
  std::string name, tag;
  std::vector<std::string> sets;  // --set values of the arm
};

// Runs a sub-process from an argument vector (no shell: nothing in a value is
// interpreted); its output goes to ours. Throws when it fails.
void run_or_fail(const std::vector<std::string>& argv, const std::string& what) {
  std::string shown = "$";
  for (const auto& a : argv) shown += " " + a;
  log::info(shown);
  const ProcessEnd end = run_process(argv);
  if (!end.started) throw NumericalError(what + ": could not start " + argv[0]);
  if (!end.ok()) throw NumericalError(what + " failed (" + end.describe() + "); see its output above");
}

// (wall_s, val_loss) pairs of a metrics.csv.
std::vector<std::pair<double, double>> val_curve(const std::string& csv) {
  std::vector<std::pair<double, double>> out;
  const train::CsvTable t = train::read_csv_table(csv);
  for (size_t r = 0; r < t.rows.size(); ++r)
    if (!t.cell(r, "val_loss").empty()) out.emplace_back(t.number(r, "wall_s"), t.number(r, "val_loss"));
  return out;
}

// --seeds "0,1,2" (default: the config's seed): InputError naming the flag for anything else.
std::vector<int64_t> parse_seeds(const AppArgs& args, const Config& cfg) {
  std::vector<int64_t> seeds;
  std::stringstream ss(args.option("--seeds", std::to_string(cfg.seed)));
  std::string tok;
  while (std::getline(ss, tok, ',')) {
    char* end = nullptr;
    const long long v = std::strtoll(tok.c_str(), &end, 10);
    if (tok.empty() || *end != '\0' || v < 0) input_error("--seeds", "expected comma-separated non-negative integers, got \"" + tok + "\"");
    if (std::find(seeds.begin(), seeds.end(), v) != seeds.end()) input_error("--seeds", "seed " + tok + " given twice");
    seeds.push_back(v);
  }
  if (seeds.empty() || args.option("--seeds", "x").back() == ',')
    input_error("--seeds", "expected comma-separated non-negative integers, got \"" + args.option("--seeds", "") + "\"");
  return seeds;
}

// The four DOE arms of the paper's Table 2 and the control without an optical cue.
std::vector<Arm> ablation_arms(const std::string& fisher_file) {
  auto doe_arm = [&](const std::string& name, const std::string& init, bool freeze) {
    return Arm{name, init + (freeze ? "_fixed" : "_learned"),
               {"optics.doe.init=\"" + init + "\"", "optics.doe.fisher_path=" + fisher_file,
                "optics.psf_source=\"simulator\"", std::string("train.freeze_doe=") + (freeze ? "true" : "false")}};
  };
  return {doe_arm("fresnel (fixed)", "fresnel", true), doe_arm("spiral (fixed)", "spiral", true),
          doe_arm("fisher (fixed)", "fisher", true), doe_arm("end-to-end (from fisher)", "fisher", false),
          {"all-in-focus control (no optical cue)", "all_in_focus", {"optics.psf_source=\"all_in_focus\"", "train.freeze_doe=true"}}};
}

const std::vector<std::string> kKeys{"hs_psnr_db", "hs_ssim", "lum_psnr_db", "lum_ssim", "depth_rmse_m", "depth_mae_m",
                                     "colorchecker_reflectance_rmse"};
const std::vector<std::string> kBaselineKeys{"baseline_upsampling_hs_psnr_db", "baseline_upsampling_hs_ssim",
                                             "baseline_wiener_hs_psnr_db", "baseline_wiener_hs_ssim",
                                             "baseline_constant_depth_rmse_m", "baseline_constant_depth_mae_m"};

using Results = std::map<std::string, std::map<std::string, std::vector<double>>>;  // arm -> metric -> per seed

// Trains and evaluates every arm at every seed (sub-processes); collects the
// test metrics and the validation curves.
Results run_arms(const AppArgs& args, const std::vector<Arm>& arms, const std::vector<int64_t>& seeds,
                 const std::function<std::vector<std::string>(const std::string&, std::vector<std::string>)>& command,
                 std::vector<viz::Series>& curves) {
  Results results;
  const std::vector<std::array<int, 3>> colours{{40, 40, 200}, {40, 160, 40}, {200, 120, 30}, {20, 20, 20}, {160, 160, 160}};
  for (size_t a = 0; a < arms.size(); ++a) {
    for (int64_t seed : seeds) {
      const std::string tag = arms[a].tag + "_seed" + std::to_string(seed);
      const std::string dir = args.out_dir + "/" + tag;
      std::vector<std::string> sets{"--set", "seed=" + std::to_string(seed)};
      for (const auto& v : arms[a].sets) sets.insert(sets.end(), {"--set", v});
      auto with = [&](std::vector<std::string> rest) {
        std::vector<std::string> v = sets;
        v.insert(v.end(), rest.begin(), rest.end());
        return v;
      };
      run_or_fail(command("hsd_train", with({"--out", dir + "/run"})), "hsd_train (" + tag + ")");
      run_or_fail(command("hsd_eval", with({"--checkpoint", dir + "/run/checkpoints/last.pt", "--out", dir + "/eval"})),
                  "hsd_eval (" + tag + ")");
      const Json m = read_json_file(dir + "/eval/metrics.json");
      for (const auto* ks : {&kKeys, &kBaselineKeys})
        for (const auto& k : *ks) {
          if (!m.contains(k)) continue;
          if (!m.at(k).is_number())  // metrics.json writes a non-finite metric as null
            throw NumericalError("arm " + tag + ": " + k + " is not a finite number in " + dir + "/eval/metrics.json");
          results[arms[a].name][k].push_back(m.at(k).get<double>());
        }
      const auto c = val_curve(dir + "/run/metrics.csv");
      viz::Series s{arms[a].name + (seeds.size() > 1 ? " s" + std::to_string(seed) : ""), {}, {}, colours[a % colours.size()]};
      for (const auto& [t, v] : c) s.x.push_back(t), s.y.push_back(v);
      curves.push_back(s);
    }
  }
  return results;
}

// "mean ± SD" of an arm's metric over seeds in printf format f (two numbers); "" when absent.
std::string mean_sd_cell(Results& results, const std::string& arm, const std::string& k, const char* f) {
  const auto it = results[arm].find(k);
  if (it == results[arm].end() || it->second.empty()) return "";
  const SampleStats st = sample_stats(it->second);
  char buf[128];
  std::snprintf(buf, sizeof buf, f, st.mean, st.sd);
  return buf;
}

// ablation.md's table and ablation.csv: mean ± SD over seeds, the baselines
// (of each arm's own sensor image: the upsampling baseline depends on the
// optics) on the same pixels.
void write_tables(Results& results, const std::vector<Arm>& arms, size_t n_seeds, std::string& md, std::string& csv) {
  auto pm = [&](const std::string& arm, const std::string& k, const char* f) { return mean_sd_cell(results, arm, k, f); };
  csv = "arm,seeds";
  for (const auto& k : kKeys) csv += "," + k + "_mean," + k + "_std";
  for (const auto& k : kBaselineKeys) csv += "," + k + "_mean," + k + "_std";
  csv += "\n";
  md += "| arm | HS PSNR [dB] | HS SSIM | lum PSNR [dB] | depth RMSE [m] | depth MAE [m] | RMSE / constant | ColorChecker RMSE |\n"
        "|---|---|---|---|---|---|---|---|\n";
  for (const auto& arm : arms) {
    csv += "\"" + arm.name + "\"," + std::to_string(n_seeds);
    for (const auto& k : kKeys) csv += "," + pm(arm.name, k, "%.6g,%.6g");
    for (const auto& k : kBaselineKeys) csv += "," + pm(arm.name, k, "%.6g,%.6g");
    csv += "\n";
    std::string ratio;
    const auto& r = results[arm.name]["depth_rmse_m"];
    const auto& b = results[arm.name]["baseline_constant_depth_rmse_m"];
    if (!r.empty() && r.size() == b.size()) {
      std::vector<double> q;
      for (size_t i = 0; i < r.size(); ++i) q.push_back(r[i] / b[i]);
      const SampleStats st = sample_stats(q);
      ratio = format("%.2f ± %.2f", st.mean, st.sd);
    }
    md += "| " + arm.name + " | " + pm(arm.name, "hs_psnr_db", "%.2f ± %.2f") + " (" +
          pm(arm.name, "baseline_upsampling_hs_psnr_db", "%.2f") + "; " + pm(arm.name, "baseline_wiener_hs_psnr_db", "%.2f") +
          ") | " + pm(arm.name, "hs_ssim", "%.3f ± %.3f") + " (" +
          pm(arm.name, "baseline_upsampling_hs_ssim", "%.3f") + ") | " + pm(arm.name, "lum_psnr_db", "%.2f ± %.2f") +
          " | " + pm(arm.name, "depth_rmse_m", "%.3f ± %.3f") + " (" +
          pm(arm.name, "baseline_constant_depth_rmse_m", "%.3f") + ") | " + pm(arm.name, "depth_mae_m", "%.3f ± %.3f") +
          " (" + pm(arm.name, "baseline_constant_depth_mae_m", "%.3f") + ") | " + ratio + " | " +
          pm(arm.name, "colorchecker_reflectance_rmse", "%.3f ± %.3f") + " |\n";
  }
}

// Pairwise: is the difference of the means larger than two standard errors
// of that difference, sqrt(s1²/n1 + s2²/n2)?
void write_pairwise(Results& results, const std::vector<Arm>& arms, std::string& md) {
  md += "\nPairwise differences (row minus column, mean over seeds); **bold** where |difference| > 2 standard errors "
        "(sqrt(s1²/n1 + s2²/n2)); needs two or more seeds.\n";
  for (const auto& [k, label] : std::vector<std::pair<std::string, std::string>>{{"depth_rmse_m", "depth RMSE [m]"},
                                                                                 {"hs_psnr_db", "HS PSNR [dB]"}}) {
    md += "\n" + label + ":\n\n| |";
    for (const auto& b : arms) md += " " + b.name + " |";
    md += "\n|---|";
    for (size_t i = 0; i < arms.size(); ++i) md += "---|";
    md += "\n";
    for (const auto& a : arms) {
      md += "| " + a.name + " |";
      for (const auto& b : arms) {
        const auto& va = results[a.name][k];
        const auto& vb = results[b.name][k];
        if (&a == &b || va.empty() || vb.empty()) {
          md += " |";
          continue;
        }
        const SampleStats sa = sample_stats(va), sb = sample_stats(vb);
        const double d = sa.mean - sb.mean;
        const double se = std::sqrt(sa.sd * sa.sd / double(sa.n) + sb.sd * sb.sd / double(sb.n));
        const bool sig = sa.n > 1 && sb.n > 1 && std::abs(d) > 2.0 * se;
        md += format(sig ? " **%+.3g** |" : " %+.3g |", d);
      }
      md += "\n";
    }
  }
}

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);  // checked before anything runs
  const std::vector<int64_t> seeds = parse_seeds(args, cfg);
  make_dirs(args.out_dir);
  const std::string bin = fs::canonical("/proc/self/exe").parent_path().string();
  std::vector<std::string> common{"--config", args.config_path};
  for (const auto& o : args.overrides) common.insert(common.end(), {"--set", o});
  auto command = [&](const std::string& app, std::vector<std::string> rest) {
    std::vector<std::string> v{bin + "/" + app};
    v.insert(v.end(), common.begin(), common.end());
    v.insert(v.end(), rest.begin(), rest.end());
    return v;
  };
  // The Fisher DOE, once (it does not depend on the seed of the network).
  const std::string fisher_dir = args.out_dir + "/fisher";
  run_or_fail(command("hsd_fisher", {"--out", fisher_dir}), "hsd_fisher");
  const std::vector<Arm> arms = ablation_arms(Json(fisher_dir + "/fisher_height.pt").dump());
  std::vector<viz::Series> curves;
  const auto t0 = std::chrono::steady_clock::now();
  Results results = run_arms(args, arms, seeds, command, curves);
  const double minutes = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / 60.0;
  std::string md = "# DOE ablation (Baek et al. 2021, Table 2 protocol)\n\nSame network, data and budget; " +
                   std::to_string(seeds.size()) + " seed(s); mean ± standard deviation over seeds; test split; " +
                   "every metric over valid pixels. Baselines in brackets, on the same pixels: upsampling alone (the " +
                   "arm's own sensor image, no network) and Wiener deconvolution + upsampling (no network) for HS " +
                   "PSNR, the constant depth for depth RMSE.\n\n";
  std::string csv;
  write_tables(results, arms, seeds.size(), md, csv);
  write_pairwise(results, arms, md);
  const Json crlb = read_json_file(fisher_dir + "/crlb.json");
  md += format("\nAggregated CRLB (hsd_fisher): fresnel %.4g, spiral %.4g, fisher %.4g.\n", crlb["fresnel"]["aggregate"].get<double>(),
               crlb["spiral"]["aggregate"].get<double>(), crlb["fisher"]["aggregate"].get<double>());
  md += format("\nWall-clock time of the whole ablation: %.1f minutes.\n", minutes);
  md += "\n![validation loss against wall-clock time](error_vs_time.png)\n";
  write_text_file(args.out_dir + "/ablation.csv", csv);
  write_text_file(args.out_dir + "/ablation.md", md);
  viz::write_line_plot(args.out_dir + "/error_vs_time.png", "validation loss against wall-clock time", "seconds", curves, true);
  write_resolved_config(cfg, args.out_dir);
  std::printf("%s", md.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_ablate", kUsage, {"--seeds"}, {}, true, true};
  spec.heap_for_large_blocks = true;  // common/app.h, keep_freed_memory
  return run_app(spec, argc, argv, run);
}
