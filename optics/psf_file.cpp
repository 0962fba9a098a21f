#include "optics/psf_file.h"

#include <cmath>
#include <cstdio>

#include <torch/torch.h>

#include "common/error.h"

namespace hsd::optics {
namespace {

std::vector<double> as_vector(const torch::Tensor& t) {
  const torch::Tensor c = t.to(torch::kFloat64).contiguous().cpu();
  return std::vector<double>(c.data_ptr<double>(), c.data_ptr<double>() + c.numel());
}

std::string list(const std::vector<double>& v, double scale) {
  std::string s;
  char buf[32];
  for (size_t i = 0; i < v.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%s%.6g", i ? ", " : "", v[i] * scale);
    s += buf;
  }
  return "[" + s + "]";
}

bool close(const std::vector<double>& a, const std::vector<double>& b, double rel) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (!(std::abs(a[i] - b[i]) <= rel * std::max(std::abs(a[i]), std::abs(b[i])))) return false;
  return true;
}

}  // namespace

PsfFile read_psf_file(const std::string& path) {
  StringDict strings;
  const TensorDict d = load_tensor_dict(path, &strings);
  PsfFile f;
  const torch::Tensor psf = dict_get(d, "psf", path);
  if (psf.dim() != 4 || psf.size(0) < 1 || psf.size(1) < 1 || psf.size(2) != psf.size(3) || psf.size(2) % 2 == 0)
    input_error(path, "entry 'psf' must be [L, Z, P, P] with P odd, is " + c10::str(psf.sizes()));
  if (!psf.is_floating_point()) input_error(path, "entry 'psf' must hold floating-point values");
  const std::string bad = first_nonfinite(psf);
  if (!bad.empty()) input_error(path, "entry 'psf' holds " + bad);
  const torch::Tensor p64 = psf.to(torch::kFloat64).cpu();
  const torch::Tensor sums = p64.sum({2, 3}), peaks = p64.amax({2, 3}), lows = p64.amin({2, 3});
  for (int64_t l = 0; l < psf.size(0); ++l)
    for (int64_t z = 0; z < psf.size(1); ++z) {
      const double s = sums[l][z].item<double>(), pk = peaks[l][z].item<double>(), lo = lows[l][z].item<double>();
      const std::string where = "slice [" + std::to_string(l) + ", " + std::to_string(z) + "] of 'psf'";
      if (!(s > 0.0) || !(pk > 0.0)) input_error(path, where + " holds no light (sum " + c10::str(s) + ")");
      if (lo < -0.1 * pk)
        input_error(path, where + " has a value of " + c10::str(lo) + " against its peak " + c10::str(pk) +
                              " (below -10 %: not an intensity)");
    }
  f.psf = (p64 / sums.view({psf.size(0), psf.size(1), 1, 1})).to(torch::kFloat32);
  f.wavelengths_m = as_vector(dict_get(d, "wavelengths_m", path));
  f.depths_m = as_vector(dict_get(d, "depths_m", path));
  if (int64_t(f.wavelengths_m.size()) != psf.size(0))
    input_error(path, "entry 'wavelengths_m' has " + std::to_string(f.wavelengths_m.size()) + " values for " +
                          std::to_string(psf.size(0)) + " bands of 'psf'");
  if (int64_t(f.depths_m.size()) != psf.size(1))
    input_error(path, "entry 'depths_m' has " + std::to_string(f.depths_m.size()) + " values for " +
                          std::to_string(psf.size(1)) + " depths of 'psf'");
  const torch::Tensor pitch = dict_get(d, "pixel_pitch_m", path);
  if (pitch.numel() != 1) input_error(path, "entry 'pixel_pitch_m' must be one number");
  f.pixel_pitch_m = pitch.to(torch::kFloat64).item<double>();
  if (!(f.pixel_pitch_m > 0.0) || !std::isfinite(f.pixel_pitch_m))
    input_error(path, "entry 'pixel_pitch_m' must be a positive number of metres");
  const auto it = strings.find("source");
  if (it != strings.end()) f.source = it->second;
  return f;
}

torch::Tensor psf_for_config(const PsfFile& file, const OpticsConfig& cfg, const std::string& path,
                             const std::string& key, torch::Device device) {
  const std::vector<double> wl = cfg.wavelengths_m();
  auto fail = [&](const std::string& what) { input_error(key, path + " " + what); };
  if (!close(file.wavelengths_m, wl, 1e-6))
    fail("holds wavelengths " + list(file.wavelengths_m, 1e9) + " nm but optics.wavelengths_nm is " + list(wl, 1e9));
  if (!close(file.depths_m, cfg.depths_m, 1e-6))
    fail("holds depths " + list(file.depths_m, 1.0) + " m but optics.depths_m is " + list(cfg.depths_m, 1.0));
  if (!close({file.pixel_pitch_m}, {cfg.pixel_pitch_m}, 1e-6))
    fail("was made with pixel pitch " + c10::str(file.pixel_pitch_m) + " m but optics.pixel_pitch_m is " +
         c10::str(cfg.pixel_pitch_m));
  if (file.psf.size(2) != cfg.psf_size)
    fail("holds " + std::to_string(file.psf.size(2)) + "-pixel PSFs but optics.psf_size is " + std::to_string(cfg.psf_size));
  return file.psf.to(device);
}

TensorDict psf_file_entries(const PsfSpec& spec, const torch::Tensor& psf, const torch::Tensor& height_m,
                            const torch::Tensor& omega) {
  auto f64 = [](const std::vector<double>& v) { return torch::tensor(v, torch::kFloat64); };
  auto scalar = [](double v) { return torch::tensor(v, torch::kFloat64); };
  TensorDict d{{"psf", psf.to(torch::kFloat32)},
               {"wavelengths_m", f64(spec.wavelengths_m)},
               {"depths_m", f64(spec.depths_m)},
               {"pixel_pitch_m", scalar(spec.pixel_pitch_m)},
               {"sensor_distance_m", scalar(spec.sensor_distance_m)},
               {"aperture_diameter_m", scalar(spec.aperture_diameter_m)},
               {"doe_pitch_m", scalar(spec.doe_pitch_m)},
               {"refractive_index", f64(spec.refractive_index)},
               {"camera_response", omega}};
  if (height_m.defined()) d["height_map_m"] = height_m.detach().to(torch::kFloat32);
  return d;
}

void write_psf_file(const std::string& path, const TensorDict& entries, const std::string& source) {
  for (const char* k : {"psf", "wavelengths_m", "depths_m", "pixel_pitch_m"})
    if (!entries.count(k)) throw std::logic_error(std::string("write_psf_file: no entry ") + k);
  save_tensor_dict(path, entries, {{"source", source}});
}

}  // namespace hsd::optics
