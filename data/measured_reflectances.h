// The training reflectances of the realistic generator: measured spectra of real
// objects, never the ColorChecker (the held-out spectral test chart).
//   * 170 object spectra of Vrhel, Gershon & Iwan, "Measurement and analysis of
//     object reflectance spectra", Color Res. Appl. 19(1), 1994 (natural
//     objects, foods, fabrics, paints, papers), 400-700 nm every 10 nm, as
//     published in ISETCam (data/real/vrhel_objects/, MATLAB file, read by
//     data/mat_file.h), band-integrated onto the config's bands
//     (data/band_resample.h; constant half a sample beyond 400 and 700 nm).
//   * Any spectrum whose shape is within `exclusion` of one of the 24
//     ColorChecker patches is dropped: distance ‖s − a·p‖ / ‖s‖ for the best
//     scale a >= 0 (the sine of the spectral angle; a darkened or brightened
//     copy of a patch is at distance 0, as shading and texture scale every
//     training spectrum). With the default 0.05, 13 of the 170 go (157 remain;
//     at 0.02, 3; at 0.08, 40). `min_distance_to_colorchecker()` reports the
//     closest that remains.
// The CAVE balloons cube is not used for training: it is the real-derived
// held-out test set (data/real_test_set.h).
#pragma once
#include <random>
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

class MeasuredReflectances {
 public:
  // InputError naming the file when the spectra cannot be read, or naming
  // data.generator.spectral_exclusion when fewer than min_spectra remain.
  MeasuredReflectances(const std::vector<double>& wavelengths_m, double band_width_m, double exclusion = 0.05,
                       int64_t min_spectra = 12);
  const torch::Tensor& spectra() const { return spectra_; }  // float64 [M, L], in [0, 1]
  int64_t size() const { return spectra_.size(0); }
  int64_t excluded() const { return excluded_; }
  double min_distance_to_colorchecker() const { return min_distance_; }
  // Shape distance of spectrum [L] to the nearest ColorChecker patch (see above).
  double distance_to_colorchecker(const torch::Tensor& spectrum) const;
  // k distinct spectra [k, L] drawn uniformly.
  torch::Tensor draw(std::mt19937_64& rng, int64_t k) const;
  static std::string source_path();

 private:
  torch::Tensor spectra_, checker_;  // [M, L], [24, L]
  int64_t excluded_ = 0;
  double min_distance_ = 0.0;
};

}  // namespace hsd::data
