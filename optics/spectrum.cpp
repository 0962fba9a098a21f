#include "optics/spectrum.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <torch/torch.h>

#include "common/build_info.h"
#include "common/error.h"
#include "common/log.h"

namespace hsd::optics {

std::string data_dir() {
  if (const char* env = std::getenv("HSD_DATA_DIR"); env && *env) return env;
  return HSD_DEFAULT_DATA_DIR;
}

std::string spectra_path(const std::string& name) { return data_dir() + "/spectra/" + name; }

namespace {
std::vector<std::string> split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::string cell;
  std::istringstream s(line);
  while (std::getline(s, cell, sep)) {
    while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
    out.push_back(cell);
  }
  if (!line.empty() && line.back() == sep) out.emplace_back();
  return out;
}
}  // namespace

SpectralTable SpectralTable::load_csv(const std::string& path) {
  std::ifstream f(path);
  if (!f) input_error(path, "cannot open spectral table");
  SpectralTable t;
  t.path_ = path;
  std::string line;
  if (!std::getline(f, line)) input_error(path, "empty file");
  auto header = split(line, ',');
  if (header.size() < 2 || header[0] != "wavelength") input_error(path, "expected a header 'wavelength,<curve>,...'");
  t.columns_.assign(header.begin() + 1, header.end());
  t.values_.assign(t.columns_.size(), {});
  int row = 1;
  while (std::getline(f, line)) {
    ++row;
    if (line.empty() || line == "\r") continue;
    auto cells = split(line, ',');
    if (cells.size() != header.size())
      input_error(path, "row " + std::to_string(row) + " has " + std::to_string(cells.size()) + " cells, expected " +
                            std::to_string(header.size()));
    try {
      t.wl_nm_.push_back(std::stod(cells[0]));
      for (size_t c = 1; c < cells.size(); ++c) t.values_[c - 1].push_back(cells[c].empty() ? 0.0 : std::stod(cells[c]));
    } catch (const std::exception&) {
      input_error(path, "row " + std::to_string(row) + " holds a non-number");
    }
    if (t.wl_nm_.size() > 1 && !(t.wl_nm_.back() > t.wl_nm_[t.wl_nm_.size() - 2]))
      input_error(path, "wavelengths must increase (row " + std::to_string(row) + ")");
  }
  if (t.wl_nm_.size() < 2) input_error(path, "needs at least two rows");
  return t;
}

bool SpectralTable::has_column(const std::string& name) const {
  return std::find(columns_.begin(), columns_.end(), name) != columns_.end();
}

size_t SpectralTable::index(const std::string& column) const {
  auto it = std::find(columns_.begin(), columns_.end(), column);
  if (it == columns_.end()) input_error(path_, "no column '" + column + "'");
  return size_t(it - columns_.begin());
}

double SpectralTable::value(const std::string& column, double x) const {
  const auto& v = values_[index(column)];
  if (x < wl_nm_.front() || x > wl_nm_.back()) return 0.0;
  auto it = std::upper_bound(wl_nm_.begin(), wl_nm_.end(), x);
  if (it == wl_nm_.end()) return v.back();
  const size_t i = size_t(it - wl_nm_.begin());
  const double t = (x - wl_nm_[i - 1]) / (wl_nm_[i] - wl_nm_[i - 1]);
  return v[i - 1] + t * (v[i] - v[i - 1]);
}

double SpectralTable::band_mean(const std::string& column, double lo, double hi) const {
  if (!(hi > lo)) input_error(path_, "band_mean needs hi > lo");
  // Exact integral of the piecewise-linear interpolant: trapezoids between the
  // band edges and every table node inside the band.
  std::vector<double> xs{lo};
  for (double w : wl_nm_)
    if (w > lo && w < hi) xs.push_back(w);
  xs.push_back(hi);
  // The interpolant jumps to 0 outside the table: split there too.
  double integral = 0.0;
  for (size_t i = 0; i + 1 < xs.size(); ++i) {
    double a = xs[i], b = xs[i + 1];
    a = std::max(a, wl_nm_.front());
    b = std::min(b, wl_nm_.back());
    if (b <= a) continue;
    integral += 0.5 * (value(column, a) + value(column, b)) * (b - a);
  }
  return integral / (hi - lo);
}

torch::Tensor camera_channel_mean(const torch::Tensor& band, const torch::Tensor& omega) {
  if (omega.dim() != 2 || band.dim() < 1 || omega.size(1) != band.size(0))
    throw InputError("camera_channel_mean: omega must be [C, L] and the bands [L, ...], got " + c10::str(omega.sizes()) +
                     " and " + c10::str(band.sizes()));
  const torch::Tensor w = omega.to(band.dtype()).to(band.device());
  const torch::Tensor sum = torch::tensordot(w, band, {1}, {0});  // [C, ...]
  std::vector<int64_t> shape(size_t(band.dim()), 1);
  shape[0] = w.size(0);
  const torch::Tensor den = w.sum(1).view(shape);
  return sum / den.clamp_min(1e-30) * (den > 0);
}

torch::Tensor camera_response(const std::string& camera, const std::vector<double>& wavelengths_m,
                              double band_width_m) {
  const std::string path = spectra_path("camera_sensitivity_" + camera + ".csv");
  std::ifstream probe(path);
  if (!probe) input_error("config key sensor.camera", "no camera table for \"" + camera + "\" (" + path + ")");
  const SpectralTable t = SpectralTable::load_csv(path);
  const int64_t L = int64_t(wavelengths_m.size());
  torch::Tensor out = torch::zeros({3, L}, torch::kFloat64);
  auto acc = out.accessor<double, 2>();
  const char* ch[3] = {"r", "g", "b"};
  const double half_nm = 0.5 * band_width_m * 1e9;
  for (int64_t l = 0; l < L; ++l) {
    const double c = wavelengths_m[size_t(l)] * 1e9;
    if (c - half_nm < t.min_nm() || c + half_nm > t.max_nm())
      log::warn("band " + std::to_string(c) + " nm extends outside the camera table (" + std::to_string(t.min_nm()) +
                "-" + std::to_string(t.max_nm()) + " nm); the response is taken as 0 outside it");
    for (int k = 0; k < 3; ++k) acc[k][l] = t.band_mean(ch[k], c - half_nm, c + half_nm);
  }
  const double largest = out.sum(1).max().item<double>();
  if (!(largest > 0.0)) input_error("config key sensor.camera", "camera \"" + camera + "\" has no response in these bands");
  return (out / largest).to(torch::kFloat32);
}

torch::Tensor illuminant_bands(const std::string& name, const std::vector<double>& wavelengths_m, double band_width_m,
                               const std::string& config_key) {
  static const SpectralTable table = SpectralTable::load_csv(spectra_path("illuminants.csv"));
  if (!table.has_column(name)) {
    std::string known;
    for (const auto& c : table.columns()) known += (known.empty() ? "" : ", ") + c;
    input_error("config key " + config_key, "unknown illuminant \"" + name + "\" (known: " + known + ")");
  }
  const double half_nm = 0.5 * band_width_m * 1e9;
  std::vector<double> v;
  for (double w : wavelengths_m) v.push_back(table.band_mean(name, w * 1e9 - half_nm, w * 1e9 + half_nm));
  torch::Tensor t = torch::tensor(v, torch::kFloat64);
  const double m = t.max().item<double>();
  if (!(m > 0.0)) input_error("config key " + config_key, "illuminant \"" + name + "\" is zero in every band");
  return (t / m).to(torch::kFloat32);
}

std::array<double, 3> wavelength_display_rgb(double wavelength_m) {
  static const SpectralTable cmf = SpectralTable::load_csv(spectra_path("cie1931_2deg_cmf.csv"));
  const double nm = wavelength_m * 1e9;
  const double X = cmf.value("x_bar", nm), Y = cmf.value("y_bar", nm), Z = cmf.value("z_bar", nm);
  // XYZ -> linear sRGB (IEC 61966-2-1, D65).
  std::array<double, 3> rgb{3.2406 * X - 1.5372 * Y - 0.4986 * Z, -0.9689 * X + 1.8758 * Y + 0.0415 * Z,
                            0.0557 * X - 0.2040 * Y + 1.0570 * Z};
  double m = 0.0;
  for (double& v : rgb) {
    v = std::max(0.0, v);
    m = std::max(m, v);
  }
  if (m <= 0.0) return {0.5, 0.5, 0.5};  // outside the visible table: grey
  for (double& v : rgb) v /= m;
  return rgb;
}

}  // namespace hsd::optics
