// The all-in-focus control: an imaging system without an optical depth or
// spectral cue, against which a DOE's contribution is measured (docs/evaluation.md:
// the control arm of hsd_ablate, optics.psf_source = "all_in_focus").
// Every band λ and depth z gets one and the same PSF,
//   P_λ,z = P_ideal   for all λ, z,
// the diffraction-limited, in-focus PSF of the aperture at the design
// wavelength λ0 (optics.doe.design_wavelength_m), integrated over pixels: the
// PSF of an ideal lens focused on the source. It is computed by the simulator
// (psf.h) for a kinoform lens at exactly its design point (λ0, z0 with z0 the
// middle depth), where the wrapped kinoform equals an ideal lens; the
// closed form it approaches is the Airy pattern (2 J1(v)/v)², v = π D r/(λ0 s).
// Only scene context (texture, shading, layout) is left for the network.
#pragma once
#include <torch/types.h>

#include "common/config.h"
#include "optics/material.h"
#include "optics/psf.h"
#include "optics/sensor.h"

namespace hsd::optics {

// [L, Z, P, P] float32 on `device`, every [l, z] slice the same in-focus PSF
// (sums to 1); L, Z, P from the config (optics.wavelengths_nm, depths_m, psf_size).
torch::Tensor all_in_focus_psf(const OpticsConfig& cfg, const Material& material, torch::Device device);

}  // namespace hsd::optics
