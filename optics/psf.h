// The hyperspectral-depth PSF stack P_λ,z of a DOE (the paper's
// "Differentiable Point Spread Function", Eq. for P_λ,z; conventions in
// optics/conventions.h): for every band λ and depth z, the intensity of a
// point source on the axis, propagated through aperture and DOE to the sensor,
// integrated over each pixel of an odd P×P window centred on the axis.
//
// Method: the Fresnel integral is evaluated at Gauss–Legendre nodes inside each
// pixel (pixel_quadrature.h) by matrix Fourier transforms (fresnel_mft.h): only
// the window's pixels are computed, at exactly the sensor pitch for every λ.
// Differentiable in the height map (autograd through every step).
#pragma once
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <torch/types.h>

#include "common/config.h"
#include "optics/material.h"

namespace hsd::optics {

// Everything the PSF depends on apart from the height map. SI units.
// make_psf_spec fills it from the config; the numerical-method settings of a
// spec built by hand default to the config's defaults (OpticsConfig in
// common/config.h, the one source of them, checked against configs/base.json
// by a test), so a library user gets the simulator the apps run.
struct PsfSpec {
  std::vector<double> wavelengths_m;     // [L] band centres
  std::vector<double> depths_m;          // [Z] source distances from the DOE
  std::vector<double> refractive_index;  // [L] η of the DOE material at each band centre
  std::vector<int> pixel_nodes;          // [L] Gauss–Legendre nodes per pixel axis
  double sensor_distance_m = 0.0;
  double pixel_pitch_m = 0.0;
  double aperture_diameter_m = 0.0;
  ApertureShape aperture_shape = OpticsConfig{}.aperture_shape;
  double doe_pitch_m = 0.0;
  int64_t doe_samples = 0;  // N
  int64_t psf_size = 0;     // P (odd)
  c10::ScalarType real_dtype = torch::kFloat32;
  torch::Device device = torch::kCPU;
  // false: autograd stores every band's intermediate tensors (fastest);
  // true: only the height map is stored and each band is recomputed in the
  // backward pass (about 1.5x the time of forward+backward, a fraction of the memory).
  bool recompute_in_backward = OpticsConfig{}.psf_backward == PsfBackward::recompute;
  // Relative singular-value cut of the low-rank tilt kernels (fresnel_mft.h);
  // 0 = the exact matrix Fourier transform.
  double mft_rank_tol = OpticsConfig{}.mft_rank_tol;
  // With mft_rank_tol > 0: also factor each wavelength's kernels jointly over
  // all depths (fresnel_mft.h, DepthBasis), so the depths share one product
  // with the pupil field. Costs a one-off factorisation per wavelength (about
  // 50 ms on the paper config) that pays back after a few calls: worth
  // it where the same simulator runs many times (training, design), not in a
  // one-shot app. The error stays within the rank cut (mft_rank_tol).
  bool depth_basis = false;
  // Pupil sub-samples per DOE cell and axis (k): the height map stays [N, N];
  // each cell of constant height is evaluated at k×k points of pitch δ/k.
  int64_t pupil_oversampling = OpticsConfig{}.pupil_oversampling;
  // How each pupil cell is integrated (fresnel_mft.h, cell_average_factor):
  // "sinc_cross" integrates the linear part of the smooth phases across the
  // cell including the cross term (two kernel terms), "sinc" without it (one
  // term), "midpoint" takes their value at the cell centre.
  CellIntegration pupil_cell_integration = OpticsConfig{}.pupil_cell_integration;
  // Wavelengths per band (K): Gauss–Legendre nodes λ_c + w·u_k across the band of
  // width band_width_m (flat spectrum inside it; 0 = the spacing of
  // wavelengths_m, 10 nm for one band, as optics.band_width_nm); the band's
  // PSF is Σ_k w_k P(λ_k). K = 1 is the band centre. With K > 1,
  // spectral_refractive_index holds η at the L·K nodes, band-major
  // (make_psf_spec fills it from the material; a spec built by hand sets it,
  // or K = 1).
  int64_t spectral_samples = OpticsConfig{}.spectral_samples;
  double band_width_m = 0.0;
  std::vector<double> spectral_refractive_index;

  bool cell_sinc() const { return pupil_cell_integration != CellIntegration::midpoint; }       // sinc factors on the cells
  int64_t cell_kernel_terms() const { return pupil_cell_integration == CellIntegration::sinc_cross ? 2 : 1; }  // G
  int64_t pupil_samples() const { return doe_samples * pupil_oversampling; }   // N·k
  double resolved_band_width_m() const;  // band_width_m, or the wavelengths' spacing when it is 0
  double pupil_pitch_m() const { return doe_pitch_m / double(pupil_oversampling); }  // δ/k
  // The L·K wavelengths and weights of the spectral quadrature, band-major.
  std::vector<double> spectral_wavelengths_m() const;
  std::vector<double> spectral_weights() const;
};

// Builds the spec from the config: indices from the material (warns outside its
// valid range), pixel nodes per band (fixed, or automatic from
// pixel_quadrature_tol), dtype from optics.precision.
PsfSpec make_psf_spec(const OpticsConfig& cfg, const Material& material, torch::Device device);

// The converged reference of a spec, what PSF accuracy is measured against
// (hsd_bench psf/sim/accuracy, the accuracy tests): float64, 8 × 8 Gauss
// nodes per pixel, the exact matrix Fourier transform (mft_rank_tol 0); the
// pupil sampling and spectral samples as in `spec`.
PsfSpec converged_reference(const PsfSpec& spec);

struct PsfStack {
  torch::Tensor psf;               // [L, Z', P, P] real_dtype; each [l, z] slice sums to 1
  torch::Tensor energy_in_window;  // [L, Z'] float64, no grad: fraction of the light through the aperture in the window
};

class PsfSimulator {
 public:
  explicit PsfSimulator(PsfSpec spec);

  // height_m: [N, N] metres (float32 or float64; may require grad).
  // depth_indices: which of spec.depths_m to compute (empty = all), in that order.
  // on_band: called after each wavelength (for progress output).
  // band_indices: which bands to compute (empty = all), in that order; the
  // result's first axis follows it.
  PsfStack compute(const torch::Tensor& height_m, const std::vector<int64_t>& depth_indices = {},
                   const std::function<void(int64_t)>& on_band = {},
                   const std::vector<int64_t>& band_indices = {}) const;

  const PsfSpec& spec() const { return spec_; }
  const torch::Tensor& aperture() const { return aperture_; }  // float64 [N, N]
  // Rank kept for each spectral node's tilt kernel (its row count M when exact), [L·K].
  std::vector<int64_t> kernel_ranks() const;
  // Rank R of each spectral node's joint depth basis, [L·K] (0 without spec.depth_basis).
  std::vector<int64_t> depth_basis_ranks() const;
  torch::ScalarType complex_dtype() const;

 private:
  PsfSpec spec_;
  torch::Tensor aperture_;              // float64 [N, N] on device
  torch::Tensor aperture_real_;         // the same in the compute dtype (shared by every band)
  torch::Tensor pupil_x_;               // float64 [N·k]
  // Per spectral node j = l·K + k (band l, sub-wavelength k):
  std::vector<double> node_wavelength_m_, node_index_, node_weight_;
  struct NodeKernel {
    torch::Tensor tilt;         // complex [P·n_l, N·k] (exact path; undefined when factored)
    torch::Tensor left, right;  // low-rank factors of the tilt kernel (if mft_rank_tol > 0)
    torch::Tensor weights;      // real [n_l], pixel Gauss-Legendre weights, sum 1
    torch::Tensor depth_left, depth_basis;  // joint factors over all depths [Z, P·n_l, R], [R, N·k] (spec.depth_basis)
  };
  struct KernelCache {
    explicit KernelCache(size_t n) : kernels(n), once(new std::once_flag[n]) {}
    std::vector<NodeKernel> kernels;
    std::unique_ptr<std::once_flag[]> once;
  };
  const NodeKernel& kernel(size_t j) const;  // built on first use
  NodeKernel build_kernel(size_t j) const;
  std::shared_ptr<KernelCache> kernels_;      // shared by copies of this simulator
  double aperture_energy_ = 0.0;        // Σ A² (δ² units)
};

}  // namespace hsd::optics
