#include "data/scene_exr.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <thread>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfStringAttribute.h>
#include <ImfThreading.h>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/error.h"

namespace hsd::data {

namespace {
// OpenEXR's (de)compression runs on its global pool, one thread per core: a
// 25-band ZIP scene reads in a fraction of the time of one thread.
int exr_threads() {
  static std::once_flag once;
  static int n = 1;
  std::call_once(once, [] {
    n = int(std::max(1u, std::thread::hardware_concurrency()));
    Imf::setGlobalThreadCount(n);
  });
  return n;
}
}  // namespace

std::optional<SpectralChannel> parse_spectral_channel(const std::string& name) {
  std::string prefix;
  if (name.rfind("T.", 0) == 0) prefix = "T";
  else if (name.rfind("S0.", 0) == 0) prefix = "S0";
  else return std::nullopt;
  std::string rest = name.substr(prefix.size() + 1);
  // Split number and unit: the unit is the trailing run of letters (and µ).
  static const std::vector<std::pair<std::string, double>> units = {
      {"nm", 1e-9}, {"um", 1e-6}, {"\xC2\xB5m", 1e-6}, {"pm", 1e-12}, {"mm", 1e-3}, {"m", 1.0}};
  for (const auto& [u, scale] : units) {
    if (rest.size() <= u.size() || rest.compare(rest.size() - u.size(), u.size(), u) != 0) continue;
    std::string num = rest.substr(0, rest.size() - u.size());
    for (char& c : num)
      if (c == ',') c = '.';
    if (num.find_first_not_of("0123456789.") != std::string::npos || num.empty()) return std::nullopt;
    try {
      size_t pos = 0;
      const double v = std::stod(num, &pos);
      if (pos != num.size() || !(v > 0.0)) return std::nullopt;
      return SpectralChannel{prefix, v * scale};
    } catch (const std::exception&) {
      return std::nullopt;
    }
  }
  return std::nullopt;
}

std::string spectral_channel_name(const std::string& prefix, double wavelength_m) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.10g", wavelength_m * 1e9);
  std::string v = buf;
  for (char& c : v)
    if (c == '.') c = ',';
  return prefix + "." + v + "nm";
}

namespace {

// Reads the named channels as float32 [C, H, W].
torch::Tensor read_channels(Imf::InputFile& file, const std::vector<std::string>& names, int64_t H, int64_t W,
                            const Imath::Box2i& dw) {
  torch::Tensor out = torch::empty({int64_t(names.size()), H, W}, torch::kFloat32);
  Imf::FrameBuffer fb;
  float* base = out.data_ptr<float>();
  for (size_t c = 0; c < names.size(); ++c) {
    float* origin = base + c * size_t(H * W) - (size_t(dw.min.y) * size_t(W) + size_t(dw.min.x));
    fb.insert(names[c], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(origin), sizeof(float), sizeof(float) * size_t(W)));
  }
  file.setFrameBuffer(fb);
  file.readPixels(dw.min.y, dw.max.y);
  return out;
}

struct OutChannel {
  std::string name;
  torch::Tensor data;  // [H, W]
  bool half = false;   // store 16-bit floats
};

void write_exr(const std::string& path, const std::vector<OutChannel>& channels,
               const std::map<std::string, std::string>& attributes) {
  if (channels.empty()) input_error(path, "no channels to write");
  const int64_t H = channels[0].data.size(0), W = channels[0].data.size(1);
  // OpenEXR does not convert pixel types on output: hand it the file's type.
  std::vector<torch::Tensor> keep;
  for (const auto& ch : channels)
    keep.push_back(ch.data.detach().to(ch.half ? torch::kHalf : torch::kFloat32).cpu().contiguous());
  write_atomically(path, [&](const std::string& tmp) {
    try {
      Imf::Header header(static_cast<int>(W), static_cast<int>(H));
      for (const auto& [k, v] : attributes) header.insert(k, Imf::StringAttribute(v));
      Imf::FrameBuffer fb;
      for (size_t c = 0; c < channels.size(); ++c) {
        const auto type = channels[c].half ? Imf::HALF : Imf::FLOAT;
        const size_t bytes = channels[c].half ? 2 : sizeof(float);
        header.channels().insert(channels[c].name, Imf::Channel(type));
        fb.insert(channels[c].name, Imf::Slice(type, static_cast<char*>(keep[c].data_ptr()), bytes, bytes * size_t(W)));
      }
      Imf::OutputFile file(tmp.c_str(), header, exr_threads());
      file.setFrameBuffer(fb);
      file.writePixels(int(H));
    } catch (const std::exception& e) {
      input_error(path, std::string("cannot write EXR (") + e.what() + ")");
    }
  });
}

std::string first_bad_pixel(const torch::Tensor& bad /* [H, W] bool */) {
  const torch::Tensor idx = bad.nonzero();
  return "e.g. at (x=" + std::to_string(idx[0][1].item<int64_t>()) + ", y=" + std::to_string(idx[0][0].item<int64_t>()) + ")";
}

}  // namespace

SpectralScene read_scene_exr(const std::string& path) {
  SpectralScene scene;
  try {
    Imf::InputFile file(path.c_str(), exr_threads());
    const Imath::Box2i dw = file.header().dataWindow();
    const int64_t W = dw.max.x - dw.min.x + 1, H = dw.max.y - dw.min.y + 1;
    if (W <= 0 || H <= 0) input_error(path, "empty data window");
    std::vector<std::pair<double, std::string>> spectral;
    std::string kind_prefix;
    bool has_z = false, has_mask = false;
    const Imf::ChannelList& cl = file.header().channels();
    for (auto it = cl.begin(); it != cl.end(); ++it) {
      const std::string name = it.name();
      if (name == "Z") has_z = true;
      else if (name == "mask") has_mask = true;
      else if ((name.rfind("T.", 0) == 0 || name.rfind("S0.", 0) == 0) && !parse_spectral_channel(name))
        input_error(path, "malformed spectral channel name \"" + name +
                              "\" (expected T.<wavelength><unit> or S0.<wavelength><unit>, e.g. T.550nm or T.552,5nm)");
      else if (auto sc = parse_spectral_channel(name)) {
        if (!kind_prefix.empty() && kind_prefix != sc->prefix)
          input_error(path, "mixes reflectance (T.) and emission (S0.) channels; use one kind per scene");
        kind_prefix = sc->prefix;
        spectral.emplace_back(sc->wavelength_m, name);
      }
    }
    if (spectral.empty()) input_error(path, "no spectral channels (expected T.<wavelength>nm or S0.<wavelength>nm)");
    if (!has_z) input_error(path, "missing depth channel Z (metres)");
    std::sort(spectral.begin(), spectral.end());
    for (size_t i = 1; i < spectral.size(); ++i)
      if (std::fabs(spectral[i].first - spectral[i - 1].first) < 1e-13)
        input_error(path, "two channels name the same wavelength (" + spectral[i - 1].second + ", " + spectral[i].second + ")");
    std::vector<std::string> names;
    for (const auto& [w, n] : spectral) {
      scene.wavelengths_m.push_back(w);
      names.push_back(n);
    }
    scene.kind = kind_prefix == "T" ? SpectralKind::Reflectance : SpectralKind::Radiance;
    // One pass over the file: OpenEXR decompresses every channel of a line
    // block whatever the frame buffer asks for, so three reads (bands, Z,
    // mask) would decompress the file three times.
    const int64_t L = int64_t(names.size());
    names.push_back("Z");
    if (has_mask) names.push_back("mask");
    const torch::Tensor all = read_channels(file, names, H, W, dw);  // [L + 1 (+ 1), H, W]
    scene.spectral = all.narrow(0, 0, L);
    scene.depth_m = all.narrow(0, L, 1);
    scene.mask = has_mask ? all.narrow(0, L + 1, 1) : torch::ones({1, H, W}, torch::kFloat32);
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    input_error(path, std::string("unreadable or truncated OpenEXR file (") + e.what() + ")");
  }
  const torch::Tensor valid = scene.mask[0] > 0.5;
  if (!valid.any().item<bool>()) input_error(path, "mask marks no pixel as valid");
  const torch::Tensor z = scene.depth_m[0];
  const torch::Tensor bad_z = valid & ~(torch::isfinite(z) & (z > 0));
  if (bad_z.any().item<bool>())
    input_error(path, "channel Z holds NaN, infinite, zero or negative depth in " + std::to_string(bad_z.sum().item<int64_t>()) +
                          " valid pixels, " + first_bad_pixel(bad_z));
  const torch::Tensor bad_s = valid & ~torch::isfinite(scene.spectral).all(0);
  if (bad_s.any().item<bool>())
    input_error(path, "spectral channels hold NaN or Inf in " + std::to_string(bad_s.sum().item<int64_t>()) +
                          " valid pixels, " + first_bad_pixel(bad_s));
  return scene;
}

void write_scene_exr(const std::string& path, const SpectralScene& scene, bool half) {
  const std::string prefix = scene.kind == SpectralKind::Reflectance ? "T" : "S0";
  if (scene.spectral.dim() != 3 || scene.spectral.size(0) != int64_t(scene.wavelengths_m.size()))
    input_error(path, "scene spectral data must be [L, H, W] with one wavelength per band");
  std::vector<OutChannel> ch;
  for (size_t l = 0; l < scene.wavelengths_m.size(); ++l)
    ch.push_back({spectral_channel_name(prefix, scene.wavelengths_m[l]), scene.spectral[int64_t(l)], half});
  ch.push_back({"Z", scene.depth_m[0], false});  // depth stays float32 (half: ~1 mm steps at 2 m)
  if (scene.mask.defined()) ch.push_back({"mask", scene.mask[0], half});
  std::map<std::string, std::string> attrs{{"spectralLayoutVersion", "1.0"}};
  if (prefix == "S0") attrs["emissiveUnits"] = "W.m^-2.sr^-1";
  write_exr(path, ch, attrs);
}

torch::Tensor read_channels_exr(const std::string& path, const std::vector<std::string>& names) {
  try {
    Imf::InputFile file(path.c_str(), exr_threads());
    for (const auto& n : names)
      if (!file.header().channels().findChannel(n)) input_error(path, "missing channel " + n);
    const Imath::Box2i dw = file.header().dataWindow();
    return read_channels(file, names, dw.max.y - dw.min.y + 1, dw.max.x - dw.min.x + 1, dw);
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    input_error(path, std::string("unreadable or truncated OpenEXR file (") + e.what() + ")");
  }
}

void write_channels_exr(const std::string& path, const torch::Tensor& image, const std::vector<std::string>& names) {
  if (image.dim() != 3 || image.size(0) != int64_t(names.size()))
    input_error(path, "image must be [C, H, W] with one name per channel");
  std::vector<OutChannel> ch;
  for (size_t c = 0; c < names.size(); ++c) ch.push_back({names[c], image[int64_t(c)], false});
  write_exr(path, ch, {});
}

}  // namespace hsd::data
