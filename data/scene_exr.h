// Spectral scenes in OpenEXR, in the layout of Fichet, Pacanowski & Wilkie,
// "An OpenEXR Layout for Spectral Images", JCGT 10(3), 2021 (docs/formats.md):
//   T.<λ><unit>   reflectance (transmittance/reflectance channels)
//   S0.<λ><unit>  emitted radiance (first Stokes component)
//   Z             depth in metres (distance from the DOE plane along the axis)
//   mask          optional: 1 = valid pixel, 0 = ignore
// <λ> uses a comma or a point as decimal separator ("T.550nm", "T.552,5nm",
// "S0.550,000000nm"); units nm, um/µm, pm, mm, m. Values are read as float32
// whether the file stores half or float.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

enum class SpectralKind { Reflectance, Radiance };

struct SpectralScene {
  std::vector<double> wavelengths_m;  // [L], ascending
  SpectralKind kind = SpectralKind::Reflectance;
  torch::Tensor spectral;  // float32 [L, H, W]
  torch::Tensor depth_m;   // float32 [1, H, W]
  torch::Tensor mask;      // float32 [1, H, W], 1 = valid (all ones if the file has none)
};

struct SpectralChannel {
  std::string prefix;  // "T" or "S0"
  double wavelength_m;
};
// Parses a spectral channel name; nullopt if it is not one.
std::optional<SpectralChannel> parse_spectral_channel(const std::string& name);
// The canonical name we write: "T.550nm", "S0.552,5nm" (comma as decimal separator).
std::string spectral_channel_name(const std::string& prefix, double wavelength_m);

// Reads and checks a scene: spectral channels of one kind, Z, optional mask;
// finite spectral values and finite positive depth in valid pixels. InputError
// naming the file and the problem otherwise (missing channels, unreadable or
// truncated file, ...).
SpectralScene read_scene_exr(const std::string& path);

// Writes a scene (atomically: temporary file + rename). half = store the
// spectral channels and the mask as 16-bit floats (Z is always float32).
void write_scene_exr(const std::string& path, const SpectralScene& scene, bool half = false);

// Reads the named channels as float32 [C, H, W]; InputError naming the file and
// the first missing channel.
torch::Tensor read_channels_exr(const std::string& path, const std::vector<std::string>& names);

// Writes float32 channels [C, H, W] with the given names (e.g. R, G, B), atomically.
void write_channels_exr(const std::string& path, const torch::Tensor& image, const std::vector<std::string>& names);

}  // namespace hsd::data
