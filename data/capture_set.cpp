#include "data/capture_set.h"

#include <filesystem>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/json_reader.h"
#include "data/image_io.h"
#include "data/scene_exr.h"

namespace hsd::data {
namespace fs = std::filesystem;

CaptureSet read_capture_set(const std::string& dir) {
  const std::string path = (fs::path(dir) / "captures.json").string();
  if (!fs::is_regular_file(path)) input_error(path, "no captures.json in the captures folder (--captures)");
  const Json j = read_json_file(path);
  if (!j.is_object()) input_error(path, "expected a JSON object");
  CaptureSet c;
  c.dir = dir;
  auto fail = [&](const std::string& key, const std::string& what) { input_error(path, "key " + key + ": " + what); };
  auto numbers = [&](const std::string& key) {
    if (!j.contains(key) || !j[key].is_array() || j[key].empty()) fail(key, "required, a non-empty array of numbers");
    std::vector<double> v;
    for (const auto& x : j[key]) {
      if (!x.is_number()) fail(key, "must hold numbers only");
      v.push_back(x.get<double>());
    }
    return v;
  };
  c.wavelengths_nm = numbers("wavelengths_nm");
  c.depths_m = numbers("depths_m");
  if (!j.contains("pixel_pitch_m") || !j["pixel_pitch_m"].is_number() || !(j["pixel_pitch_m"].get<double>() > 0))
    fail("pixel_pitch_m", "required, a positive number of metres");
  c.pixel_pitch_m = j["pixel_pitch_m"].get<double>();
  auto names = [&](const Json& e, const std::string& key) {
    std::vector<std::string> out;
    const auto one = [&](const Json& s) {
      if (!s.is_string() || s.get<std::string>().empty()) fail(key, "file names must be non-empty strings");
      const std::string p = (fs::path(dir) / s.get<std::string>()).string();
      if (!fs::is_regular_file(p)) input_error(p, "no such capture file (" + path + ", key " + key + ")");
      out.push_back(p);
    };
    if (e.is_array()) {
      if (e.empty()) fail(key, "an empty list of exposures");
      for (const auto& s : e) one(s);
    } else {
      one(e);
    }
    return out;
  };
  if (!j.contains("files") || !j["files"].is_array() || j["files"].size() != c.wavelengths_nm.size())
    fail("files", "required, an array with one entry per band (" + std::to_string(c.wavelengths_nm.size()) + ")");
  for (size_t l = 0; l < c.wavelengths_nm.size(); ++l) {
    const Json& row = j["files"][l];
    const std::string key = "files[" + std::to_string(l) + "]";
    if (!row.is_array() || row.size() != c.depths_m.size())
      fail(key, "must be an array with one entry per depth (" + std::to_string(c.depths_m.size()) + ")");
    c.files.emplace_back();
    for (size_t z = 0; z < c.depths_m.size(); ++z) c.files.back().push_back(names(row[z], key + "[" + std::to_string(z) + "]"));
  }
  if (j.contains("dark")) c.dark = names(j["dark"], "dark");
  if (j.contains("axis_px")) {
    const Json& a = j["axis_px"];
    if (!a.is_array() || a.size() != 2 || !a[0].is_number() || !a[1].is_number())
      fail("axis_px", "must be [row, col] in pixels");
    c.axis_px = std::make_pair(a[0].get<double>(), a[1].get<double>());
  }
  if (j.contains("saturation")) {
    if (!j["saturation"].is_number() || !(j["saturation"].get<double>() > 0)) fail("saturation", "must be a positive number of counts");
    c.saturation = j["saturation"].get<double>();
  }
  for (auto it = j.begin(); it != j.end(); ++it) {
    static const std::vector<std::string> known{"wavelengths_nm", "depths_m", "files", "dark", "pixel_pitch_m", "axis_px", "saturation", "_note"};
    if (std::find(known.begin(), known.end(), it.key()) == known.end()) fail(it.key(), "unknown key");
  }
  return c;
}

CaptureFrame read_capture_frames(const std::vector<std::string>& paths) {
  CaptureFrame out;
  for (const auto& p : paths) {
    torch::Tensor t;
    double sat = 0.0;
    const std::string ext = fs::path(p).extension().string();
    if (ext == ".exr" || ext == ".EXR") {
      t = read_channels_exr(p, {"Y"})[0].to(torch::kFloat64);
    } else {
      const cv::Mat m = read_image(p, cv::IMREAD_UNCHANGED, "captures.json");
      if (m.channels() != 1) input_error(p, "expected a single-channel (raw) image, has " + std::to_string(m.channels()) + " channels");
      if (m.depth() == CV_16U) sat = 65535.0;
      else if (m.depth() == CV_8U) sat = 255.0;
      else input_error(p, "expected an 8- or 16-bit integer image (or EXR with channel Y)");
      cv::Mat d;
      m.convertTo(d, CV_64F);
      t = torch::from_blob(d.data, {d.rows, d.cols}, torch::kFloat64).clone();
    }
    if (!out.counts.defined()) {
      out.counts = t;
      out.saturation = sat;
    } else {
      if (t.sizes() != out.counts.sizes())
        input_error(p, "is " + c10::str(t.sizes()) + " but the other exposures of its slice are " + c10::str(out.counts.sizes()));
      out.counts = out.counts + t;
    }
  }
  out.counts = out.counts / double(paths.size());
  return out;
}

void write_png16(const std::string& path, const torch::Tensor& counts) {
  const torch::Tensor c = counts.to(torch::kFloat64).round().clamp(0.0, 65535.0).to(torch::kInt32).contiguous().cpu();
  cv::Mat m(int(c.size(0)), int(c.size(1)), CV_16U);
  const int32_t* src = c.data_ptr<int32_t>();
  for (int r = 0; r < m.rows; ++r)
    for (int k = 0; k < m.cols; ++k) m.at<uint16_t>(r, k) = uint16_t(src[int64_t(r) * m.cols + k]);
  std::vector<uchar> buf;
  if (!cv::imencode(".png", m, buf)) throw std::runtime_error("could not encode " + path);
  write_binary_file(path, std::vector<char>(buf.begin(), buf.end()));
}

}  // namespace hsd::data
