// A folder of point-source captures for hsd_calibrate: DIR/captures.json
// (docs/formats.md, "Measured PSFs") and its image files. Keys:
//   wavelengths_nm   [L] band centres of the captures
//   depths_m         [Z] point-source distances from the DOE
//   files            [L][Z] file names relative to DIR; an entry may also be
//                    an array of names: several exposures, averaged
//   dark             optional: a dark frame (or array of them, averaged)
//   pixel_pitch_m    the sensor's pixel pitch
//   axis_px          optional: the optical axis in the frames, [row, col]
//                    (pixel centres at integers); calibration registers to it
//   saturation       optional: counts at which the sensor clips (default: the
//                    largest value of the file's integer type; none for EXR)
// Images: single-channel 8- or 16-bit PNG or TIFF (raw, linear counts), or
// OpenEXR with one channel Y.
#pragma once
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

struct CaptureSet {
  std::string dir;
  std::vector<double> wavelengths_nm, depths_m;
  std::vector<std::vector<std::vector<std::string>>> files;  // [L][Z][frames], paths including dir
  std::vector<std::string> dark;                             // paths; empty = none
  double pixel_pitch_m = 0.0;
  std::optional<std::pair<double, double>> axis_px;
  double saturation = -1.0;  // < 0: from each file's type
};

// Reads DIR/captures.json; InputError naming the file and key for anything
// missing, of the wrong type or shape, or naming a file that does not exist.
CaptureSet read_capture_set(const std::string& dir);

struct CaptureFrame {
  torch::Tensor counts;     // float64 [H, W]
  double saturation = 0.0;  // the file type's largest value (65535, 255; 0 for EXR)
};
// One image file; several are averaged (same size required). InputError naming the file.
CaptureFrame read_capture_frames(const std::vector<std::string>& paths);

// Writes a 16-bit single-channel PNG of whole counts [H, W] (clipped to
// [0, 65535]) atomically.
void write_png16(const std::string& path, const torch::Tensor& counts);

}  // namespace hsd::data
