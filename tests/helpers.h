// Small builders shared by the tests: PSF specs on tiny grids.
#pragma once
#include <array>
#include <cstdio>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <stdexcept>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

#include <torch/torch.h>

#include "common/config.h"
#include "optics/psf.h"
#include "train/distributed.h"
#include "train/metrics_csv.h"

namespace hsd::test {

inline std::string source_path(const std::string& rel) { return std::string(HSD_SOURCE_DIR) + "/" + rel; }

// A random symmetric positive-definite L x L covariance, float64 (a spectral prior's Σ).
inline torch::Tensor random_spd(int64_t L, double scale) {
  const torch::Tensor a = torch::rand({L, L}, torch::kFloat64);
  return scale * (torch::matmul(a, a.t()) + 0.1 * torch::eye(L, torch::kFloat64));
}

// Random PSFs [L, K, P, P] in float64, each summing to 1, every pixel at least `floor` before normalising.
inline torch::Tensor random_band_psfs(int64_t L, int64_t K, int64_t P, double floor) {
  const torch::Tensor p = torch::rand({L, K, P, P}, torch::kFloat64) + floor;
  return p / p.sum({2, 3}, true);
}

// A spec with explicit geometry; indices constant unless given.
inline optics::PsfSpec make_spec(std::vector<double> wavelengths_m, std::vector<double> depths_m, int64_t n,
                                 double doe_pitch_m, double aperture_m, int64_t psf_size, double pixel_pitch_m,
                                 double sensor_distance_m, int nodes, c10::ScalarType dtype = torch::kFloat64,
                                 double refractive_index = 1.5) {
  optics::PsfSpec s;
  s.wavelengths_m = std::move(wavelengths_m);
  s.depths_m = std::move(depths_m);
  s.refractive_index.assign(s.wavelengths_m.size(), refractive_index);
  s.pixel_nodes.assign(s.wavelengths_m.size(), nodes);
  s.doe_samples = n;
  s.doe_pitch_m = doe_pitch_m;
  s.aperture_diameter_m = aperture_m;
  s.psf_size = psf_size;
  s.pixel_pitch_m = pixel_pitch_m;
  s.sensor_distance_m = sensor_distance_m;
  s.real_dtype = dtype;
  // What the optics tests were written for: one wavelength per band (no
  // material dispersion to interpolate) and a tight rank cut (the config's
  // defaults are 2 and 1e-4).
  s.spectral_samples = 1;
  s.mft_rank_tol = 1e-6;
  return s;
}

// A float64 gradient check of a scalar f(image, psf): autograd's gradient
// beside the central difference (step h) at three entries of each input (the
// first, one a third in, the last).
struct GradientPair {
  std::string input;  // "image" or "psf"
  int64_t entry;
  double autograd, difference;
};
inline std::vector<GradientPair> image_psf_gradient_check(
    const std::function<torch::Tensor(const torch::Tensor&, const torch::Tensor&)>& f, const torch::Tensor& image,
    const torch::Tensor& psf, double h) {
  const torch::Tensor x = image.detach().clone().requires_grad_(), p = psf.detach().clone().requires_grad_();
  f(x, p).backward();
  torch::NoGradGuard ng;
  std::vector<GradientPair> out;
  for (int which = 0; which < 2; ++which) {
    const torch::Tensor& t = which == 0 ? x : p;
    const torch::Tensor g = t.grad();
    for (int64_t i : {int64_t(0), t.numel() / 3, t.numel() - 1}) {
      torch::Tensor tp = t.detach().clone(), tm = t.detach().clone();
      tp.view(-1)[i] += h;
      tm.view(-1)[i] -= h;
      const double fd = which == 0 ? (f(tp, p) - f(tm, p)).item<double>() / (2 * h)
                                   : (f(x, tp) - f(x, tm)).item<double>() / (2 * h);
      out.push_back({which == 0 ? "image" : "psf", i, g.view(-1)[i].item<double>(), fd});
    }
  }
  return out;
}

// Centroid (x = column, y = row) of a [P, P] image in pixels from the centre.
inline std::pair<double, double> centroid(const torch::Tensor& img) {
  const int64_t P = img.size(0);
  const torch::Tensor c = torch::arange(P, torch::kFloat64) - double(P / 2);
  const torch::Tensor w = img.to(torch::kFloat64);
  const double tot = w.sum().item<double>();
  return {(w.sum(0) * c).sum().item<double>() / tot, (w.sum(1) * c).sum().item<double>() / tot};
}

// --set flags for a tiny training run on configs/tiny.json with its data in
// data_root (a few seconds): a 4-wide, 2-level network, 16-px patches, 2
// training, 1 validation and 1 test scene of 48 x 40 px, `steps` steps of 2 patches.
inline std::string tiny_run_sets(const std::filesystem::path& data_root, int steps = 2) {
  return " --set data.root=" + data_root.string() +
         " --set model.base_width=4 --set model.levels=2 --set train.batch_size=2 --set train.steps=" + std::to_string(steps) +
         " --set train.val_patches=2 --set data.patch_size_px=16 --set data.generator.train_scenes=2"
         " --set data.generator.val_scenes=1 --set data.generator.test_scenes=1 --set data.generator.width_px=48"
         " --set data.generator.height_px=40";
}

// Column `name` of a metrics.csv, one value per row; NaN where the row leaves
// it empty. Throws if the header has no such column.
inline std::vector<double> csv_column(const std::filesystem::path& csv, const std::string& name) {
  const train::CsvTable t = train::read_csv_table(csv.string());
  if (!t.has(name)) throw std::runtime_error(csv.string() + " has no column " + name);
  std::vector<double> v;
  for (size_t r = 0; r < t.rows.size(); ++r) v.push_back(t.number(r, name));
  return v;
}

// Apps as a user runs them: from the source folder, stdout dropped.
struct Run {
  int code;
  std::string err;
};
inline Run run(const std::string& args) {
  // One file per test process: ctest -j runs test cases side by side.
  const auto errfile = std::filesystem::temp_directory_path() / ("hsd_test_app_stderr_" + std::to_string(::getpid()) + ".txt");
  const std::string cmd = "cd " + std::string(HSD_SOURCE_DIR) + " && " + std::string(HSD_BIN_DIR) + "/" + args +
                          " > /dev/null 2> " + errfile.string();
  const int status = std::system(cmd.c_str());
  std::string err;
  if (FILE* f = std::fopen(errfile.c_str(), "r")) {
    std::array<char, 4096> buf{};
    size_t n;
    while ((n = std::fread(buf.data(), 1, buf.size(), f)) > 0) err.append(buf.data(), n);
    std::fclose(f);
  }
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, err};
}
// Runs a shell command and returns its stdout and exit code.
inline std::pair<std::string, int> capture(const std::string& cmd) {
  std::string out;
  int code = -1;
  if (FILE* f = popen(cmd.c_str(), "r")) {
    char buf[4096];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, f)) > 0) out.append(buf, n);
    const int status = pclose(f);
    code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  return {out, code};
}

// hsd_train as two ranks on this host (WORLD_SIZE=2, a free MASTER_PORT), run
// from the source folder: rank 0 with args0 (its output dropped), rank 1 with
// args1 (its stderr kept). Returns rank 1's stderr and the lines "rank0=<exit
// code>" and "rank1=<exit code>".
inline std::string two_rank_train(const std::string& args0, const std::string& args1) {
  const std::string env = "WORLD_SIZE=2 MASTER_ADDR=127.0.0.1 MASTER_PORT=" + std::to_string(train::free_local_port());
  const std::string bin = std::string(HSD_BIN_DIR) + "/hsd_train", src = std::string(HSD_SOURCE_DIR);
  return capture("cd " + src + " && (env " + env + " RANK=0 " + bin + args0 + " > /dev/null 2>&1; echo \"rank0=$?\") & (cd " +
                 src + " && env " + env + " RANK=1 " + bin + args1 + " 2>&1 >/dev/null; echo \"rank1=$?\"); wait")
      .first;
}

}  // namespace hsd::test
