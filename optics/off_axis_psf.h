// The PSF of a point source off the optical axis (the paper's 0 vs 8 degree
// check that justifies a shift-invariant image model). The source sits at the
// field angle θ in the x-z plane, at (x0, 0, −z) with x0 = z tan θ; its chief
// ray through the DOE's centre meets the sensor at u0 = −s tan θ, and the
// P × P window is centred there (pixel [P/2, P/2] at u0).
//
// Model (the Fresnel approximation taken about the chief ray, "tilted
// Fresnel"): with c = cos θ, r0 = z / c and R0 = s / c the source's and the
// sensor point's distances along the chief ray,
//   F(Δu, v) = Σ_x Σ_y M(x, y) e^{iψ(x, y)} Kx(Δu, x) Ky(v, y),
//   Kx = exp(−ik c² Δu x / R0) exp(ik c² x² (1/r0 + 1/R0) / 2),
//   Ky = exp(−ik v y / R0)     exp(ik y² (1/r0 + 1/R0) / 2),
// M the aperture and DOE phase (compute_pupil_field), Δu = u − u0 and v the
// sensor coordinates, and ψ the source's exact spherical phase k (r − r0)
// minus its linear (−k x sin θ, cancelled by the propagation's) and quadratic
// parts (in float64, r − r0 = (x² − 2 x x0 + y²) / (r + r0)). The x axis sees
// the tilt as the factor c² (astigmatism and a c² scale of the PSF in x);
// θ = 0 is the on-axis simulator's paraxial model up to ψ's spherical terms
// (k ρ⁴ / 8z³, 1e-5 rad for a 1-mm radius at 0.5 m).
// Limits: the propagation's third-order terms are dropped (peak phase about
// k a³ sin θ / (2 R0²) for a pupil radius a: reported by the caller); pupil
// cells are sampled at their centres (the midpoint rule), pixels integrated
// with the spec's Gauss nodes, bands with its spectral quadrature. float64,
// exact matrix products, no gradient: an analysis tool, not a training path.
#pragma once
#include <torch/types.h>

#include "optics/psf.h"

namespace hsd::optics {

// [L, Z, P, P] float64, each slice summing to 1, for height_m [N, N] and the
// field angle θ [rad] (|θ| < 30°).
torch::Tensor off_axis_psf(const PsfSpec& spec, const torch::Tensor& height_m, double field_angle_rad);

// The neglected third-order propagation phase at the aperture's edge [rad],
// k a³ sin θ / (2 R0²), at the shortest wavelength.
double off_axis_neglected_phase_rad(const PsfSpec& spec, double field_angle_rad);

}  // namespace hsd::optics
