// Spectral augmentation (the paper's "29 CIE illuminants" turning 18 reflectance
// scenes into 522 radiance images): radiance = reflectance × illuminant, both
// band-integrated over the config's bands, times a random global intensity.
//
// Which 29 (data.illuminants; the default list): every illuminant of
// data/spectra/illuminants.csv that is a distinct physical light source class:
//   A (incandescent), D50, D55, D65, D75 (daylight phases),
//   FL1-FL12 (the CIE fluorescent set: standard, broadband, three-band),
//   HP1-HP5 (high-pressure sodium / metal halide),
//   LED-B1-B5, LED-BH1, LED-RGB1 (phosphor, hybrid and RGB white LEDs).
// Left out: E (equal energy, not a source), B and C (filtered-tungsten
// daylight simulators superseded by the D series), ID50/ID65 (indoor daylight,
// close to D50/D65), FL3.1-FL3.15 (15 more fluorescents would make fluorescent
// spikes half of all lighting), LED-V1/V2 (violet-pumped, nearly identical to
// the blue-pumped LEDs within 420-660 nm).
#pragma once
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

class IlluminantBank {
 public:
  // Band means of each named illuminant, each scaled to a maximum of 1 over the
  // bands. InputError naming data.illuminants[i] for an unknown name.
  IlluminantBank(const std::vector<std::string>& names, const std::vector<double>& wavelengths_m, double band_width_m);
  int64_t size() const { return int64_t(names_.size()); }
  const std::vector<std::string>& names() const { return names_; }
  const torch::Tensor& spectra() const { return spectra_; }  // float32 [K, L]
  torch::Tensor spectrum(int64_t k) const { return spectra_[k]; }

 private:
  std::vector<std::string> names_;
  torch::Tensor spectra_;
};

// reflectance [L, H, W] (or [B, L, H, W]) × illuminant [L] × scale -> radiance, same shape.
torch::Tensor light_reflectance(const torch::Tensor& reflectance, const torch::Tensor& illuminant, double scale = 1.0);

// A random lighting: an illuminant index and a global intensity in [lo, hi].
struct Lighting {
  int64_t illuminant = 0;
  double scale = 1.0;
};
Lighting draw_lighting(std::mt19937_64& rng, int64_t illuminants, double lo, double hi);

}  // namespace hsd::data
