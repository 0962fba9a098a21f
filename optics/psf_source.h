// Where the imaging PSFs come from (optics.psf_source): the DOE's, computed by
// the simulator (psf.h, differentiable in the height map), or a fixed stack
// that ignores the height map: the all-in-focus control (all_in_focus.h) or a
// psf.pt file (psf_file.h: measured by hsd_calibrate, or from another tool).
// A fixed stack is handed to the sensor model as a PsfProvider (sensor.h).
#pragma once
#include <string>
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "optics/material.h"
#include "optics/psf.h"
#include "optics/sensor.h"

namespace hsd::optics {

// A PsfProvider that hands out slices of a fixed stack [L, Z, P, P]
// (the height map is ignored; no gradient reaches it).
PsfProvider fixed_psf_provider(const torch::Tensor& psf);

// "file:PATH" -> PATH; "" for any other source.
std::string psf_file_path(const OpticsConfig& cfg);

// The fixed stack [L, Z, P, P] float32 on `device` of optics.psf_source: the
// all-in-focus control's, or the file's (checked against the config: exit 2
// naming optics.psf_source); undefined for "simulator".
torch::Tensor fixed_psf_stack(const OpticsConfig& cfg, const Material& material, torch::Device device);

// The imaging PSFs' provider of optics.psf_source: fixed_psf_provider of the
// stack above, or nullptr for "simulator" (the DOE's PSFs from a PsfSimulator).
PsfProvider psf_source_provider(const OpticsConfig& cfg, const Material& material, torch::Device device);

// Every band's and depth's imaging PSF [L, Z, P, P] for the height map [N, N]:
// the provider's (when given) or the simulator's; no gradient.
torch::Tensor imaging_psf_stack(const PsfSimulator& sim, const torch::Tensor& height_m, const PsfProvider& provider);

}  // namespace hsd::optics
