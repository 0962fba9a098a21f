// Spectral tables (camera sensitivities, CIE colour-matching functions,
// illuminants, reflectances) and their integration over spectral bands.
//
// A band b with centre λ_b and width Δ stands for the interval
// [λ_b − Δ/2, λ_b + Δ/2]; a band's value is the mean of the tabulated curve over
// it, the curve being the piecewise-linear interpolant of the table (integrated
// exactly, not point-sampled). This is how the camera response Ω_c,λ of the
// paper's image formation J_c = Σ_λ Ω_c,λ (...) is obtained per band.
#pragma once
#include <array>
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::optics {

// Folder holding spectra/ (HSD_DATA_DIR in the environment, else the build's default).
std::string data_dir();
// data_dir() + "/spectra/" + name
std::string spectra_path(const std::string& name);

// A CSV table with a "wavelength" column in nm and one column per curve.
class SpectralTable {
 public:
  // InputError naming the file for a missing file, bad header or bad numbers.
  static SpectralTable load_csv(const std::string& path);

  const std::vector<std::string>& columns() const { return columns_; }
  bool has_column(const std::string& name) const;
  double min_nm() const { return wl_nm_.front(); }
  double max_nm() const { return wl_nm_.back(); }

  // Piecewise-linear value at λ [nm]; 0 outside the table (and empty cells are 0).
  double value(const std::string& column, double lambda_nm) const;
  // Mean of the piecewise-linear curve over [lo_nm, hi_nm] (exact integral / width).
  // Outside the table the curve is 0. Requires hi_nm > lo_nm.
  double band_mean(const std::string& column, double lo_nm, double hi_nm) const;

 private:
  size_t index(const std::string& column) const;
  std::string path_;
  std::vector<std::string> columns_;
  std::vector<double> wl_nm_;
  std::vector<std::vector<double>> values_;  // [column][row]
};

// Camera response Ω: float32 [3, L] (rows R, G, B), band means of
// data/spectra/camera_sensitivity_<camera>.csv over each band, scaled so the
// largest row sums to 1: a radiance of 1 in every band gives at most 1 (the
// saturation level) in any channel. Warns when a band leaves the table's range.
torch::Tensor camera_response(const std::string& camera, const std::vector<double>& wavelengths_m,
                              double band_width_m);

// What a camera channel sees of per-band images or PSFs: band [L, ...] ->
// [C, ...], Σ_l Ω_cl band_l / Σ_l Ω_cl (a channel with no response gives
// zeros). Ω [C, L] (camera_response); any float dtype, the band's kept.
torch::Tensor camera_channel_mean(const torch::Tensor& band, const torch::Tensor& omega);

// Illuminant spectral power per band: float32 [L], band means of the column
// `name` of data/spectra/illuminants.csv, scaled to a maximum of 1. A
// reflectance scene's radiance is reflectance × this. InputError naming
// config_key for an unknown name.
torch::Tensor illuminant_bands(const std::string& name, const std::vector<double>& wavelengths_m, double band_width_m,
                               const std::string& config_key = "sensor.illuminant");

// Display colour of a monochromatic wavelength: CIE 1931 x̄ȳz̄ -> linear sRGB,
// negatives clipped, brightest channel scaled to 1. For tinting PSF plots.
std::array<double, 3> wavelength_display_rgb(double wavelength_m);

}  // namespace hsd::optics
