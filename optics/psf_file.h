// The PSF stack file psf.pt (docs/formats.md, "Files"): written by
// hsd_psf (simulated) and hsd_calibrate (measured), read by
// optics.psf_source = "file:PATH" so that training, evaluation and simulation
// image through a given stack instead of the simulator. A dict of tensors:
//   psf               float32 [L, Z, P, P], P odd, each [l, z] slice sums to 1;
//                     the optical axis (or, for measured stacks, the slice's
//                     centroid) at the centre of pixel [P/2, P/2]
//   wavelengths_m     float64 [L]   band centres
//   depths_m          float64 [Z]   point-source distances from the DOE
//   pixel_pitch_m     float64 []    sensor pixel pitch
// plus optional entries (energy_in_window, geometry, height map, per-slice
// background and SNR of measured stacks) and the text entry `source`
// ("simulated" or "measured").
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "common/tensor_io.h"
#include "optics/psf.h"

namespace hsd::optics {

struct PsfFile {
  torch::Tensor psf;  // float32 [L, Z, P, P]; slices sum to 1 (renormalised on reading)
  std::vector<double> wavelengths_m, depths_m;
  double pixel_pitch_m = 0.0;
  std::string source;  // "simulated", "measured", or "" when the file does not say
};

// Reads and checks a psf.pt: every required entry present with its shape,
// finite values, P odd, every slice with a positive sum and no value below
// -10 % of its peak (a measured stack carries zero-mean noise after the
// background is subtracted; more negative than that is not a PSF). Slices are
// renormalised to sum 1 (exactly, in float64 before the cast). InputError
// naming the file and the entry otherwise.
PsfFile read_psf_file(const std::string& path);

// The stack of `file` for the config: its wavelengths, depths (relative 1e-6),
// pixel pitch (relative 1e-6) and window (optics.psf_size) must be the
// config's, else InputError naming `key` (what named the file: "config key
// optics.psf_source", a flag)
// and what differs. Returns psf [L, Z, P, P] float32 on `device`.
torch::Tensor psf_for_config(const PsfFile& file, const OpticsConfig& cfg, const std::string& path,
                             const std::string& key, torch::Device device);

// The contract's entries of a stack psf [L, Z, P, P] made with `spec`: psf
// (float32), wavelengths_m, depths_m, the geometry scalars, refractive_index,
// camera_response (omega [3, L]) and, when defined, height_map_m (float32).
TensorDict psf_file_entries(const PsfSpec& spec, const torch::Tensor& psf, const torch::Tensor& height_m,
                            const torch::Tensor& omega);

// Writes `entries` (which must hold psf, wavelengths_m, depths_m and
// pixel_pitch_m; others are kept as they are) and the text entry source
// atomically to `path`.
void write_psf_file(const std::string& path, const TensorDict& entries, const std::string& source);

}  // namespace hsd::optics
