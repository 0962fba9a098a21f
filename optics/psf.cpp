#include "optics/psf.h"

#include <cmath>

#include <torch/torch.h>

#include "common/error.h"
#include "optics/aperture.h"
#include "optics/fresnel_mft.h"
#include "optics/pixel_quadrature.h"

namespace hsd::optics {

PsfSpec make_psf_spec(const OpticsConfig& cfg, const Material& material, torch::Device device) {
  PsfSpec s;
  s.wavelengths_m = cfg.wavelengths_m();
  s.depths_m = cfg.depths_m;
  s.refractive_index = material.indices(s.wavelengths_m);
  s.sensor_distance_m = cfg.sensor_distance_m;
  s.pixel_pitch_m = cfg.pixel_pitch_m;
  s.aperture_diameter_m = cfg.aperture_diameter_m;
  s.aperture_shape = cfg.aperture_shape;
  s.doe_pitch_m = cfg.doe_pitch_m;
  s.doe_samples = cfg.doe_samples;
  s.psf_size = cfg.psf_size;
  s.real_dtype = cfg.precision == "float64" ? torch::kFloat64 : torch::kFloat32;
  s.device = device;
  for (double w : s.wavelengths_m) {
    if (cfg.pixel_quadrature_nodes > 0) {
      s.pixel_nodes.push_back(int(cfg.pixel_quadrature_nodes));
    } else {
      const double cpp = intensity_cycles_per_pixel(s.aperture_diameter_m, s.pixel_pitch_m, w, s.sensor_distance_m);
      s.pixel_nodes.push_back(choose_pixel_nodes(cpp, cfg.pixel_quadrature_tol));
    }
  }
  return s;
}

torch::ScalarType PsfSimulator::complex_dtype() const {
  return spec_.real_dtype == torch::kFloat64 ? torch::kComplexDouble : torch::kComplexFloat;
}

PsfSimulator::PsfSimulator(PsfSpec spec) : spec_(std::move(spec)) {
  const auto& s = spec_;
  const size_t L = s.wavelengths_m.size();
  if (L == 0 || s.depths_m.empty()) throw InputError("PSF: needs at least one wavelength and one depth");
  if (s.refractive_index.size() != L || s.pixel_nodes.size() != L)
    throw InputError("PSF: refractive_index and pixel_nodes need one entry per wavelength");
  if (s.psf_size < 1 || s.psf_size % 2 == 0) throw InputError("PSF: psf_size must be odd");
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(s.device);
  aperture_ = aperture_transmission(s.doe_samples, s.doe_pitch_m, s.aperture_diameter_m, s.aperture_shape).to(f64);
  aperture_energy_ = aperture_.pow(2).sum().item<double>();
  if (!(aperture_energy_ > 0.0)) throw InputError("PSF: the aperture covers no DOE sample");
  pupil_x_ = centred_coordinates(s.doe_samples, s.doe_pitch_m).to(f64);
  const torch::Tensor pixel_x = centred_coordinates(s.psf_size, s.pixel_pitch_m);  // [P]
  const auto cdt = complex_dtype();
  for (size_t l = 0; l < L; ++l) {
    const Quadrature1D q = gauss_legendre(s.pixel_nodes[l]);
    const torch::Tensor nodes = torch::tensor(q.nodes, torch::kFloat64) * s.pixel_pitch_m;    // [n]
    const torch::Tensor sensor_x = (pixel_x.view({-1, 1}) + nodes.view({1, -1})).reshape(-1);  // [P·n], pixel-major
    tilt_.push_back(compute_tilt_kernel(sensor_x.to(f64), pupil_x_, s.wavelengths_m[l], s.sensor_distance_m, cdt));
    const torch::Tensor w = torch::tensor(q.weights, torch::kFloat64);
    weights_.push_back(torch::outer(w, w).to(torch::TensorOptions().dtype(s.real_dtype).device(s.device)));
  }
}

PsfStack PsfSimulator::compute(const torch::Tensor& height_m, const std::vector<int64_t>& depth_indices,
                               const std::function<void(int64_t)>& on_band) const {
  const auto& s = spec_;
  const int64_t N = s.doe_samples, P = s.psf_size;
  if (height_m.dim() != 2 || height_m.size(0) != N || height_m.size(1) != N)
    throw InputError("PSF: height map must be [" + std::to_string(N) + ", " + std::to_string(N) + "], got " +
                     c10::str(height_m.sizes()));
  std::vector<int64_t> zi = depth_indices;
  if (zi.empty())
    for (int64_t z = 0; z < int64_t(s.depths_m.size()); ++z) zi.push_back(z);
  for (int64_t z : zi)
    if (z < 0 || z >= int64_t(s.depths_m.size())) throw InputError("PSF: depth index out of range");
  const int64_t Z = int64_t(zi.size());
  const auto cdt = complex_dtype();
  const torch::Tensor h = height_m.to(s.device);
  check_finite(h, "DOE height map (input of the PSF simulator)");

  std::vector<torch::Tensor> psfs, energies;
  for (size_t l = 0; l < s.wavelengths_m.size(); ++l) {
    const double lambda = s.wavelengths_m[l];
    const int64_t n = s.pixel_nodes[l];
    const torch::Tensor field = compute_pupil_field(aperture_, h, lambda, s.refractive_index[l], cdt);  // [N, N]
    std::vector<torch::Tensor> kz;
    for (int64_t z : zi) {
      const torch::Tensor chirp = compute_defocus_chirp(pupil_x_, lambda, s.depths_m[size_t(z)], s.sensor_distance_m, cdt);
      kz.push_back(tilt_[l] * chirp.view({1, N}));  // [P·n, N]
    }
    const torch::Tensor kernels = torch::stack(kz);                                    // [Z, P·n, N]
    const torch::Tensor I = intensity(matrix_fourier_transform(kernels, field));       // [Z, P·n, P·n]
    // Pixel integral: Gauss–Legendre weights over each pixel's n×n nodes.
    const torch::Tensor pix = (I.view({Z, P, n, P, n}) * weights_[l].view({1, 1, n, 1, n})).sum({2, 4});  // [Z, P, P]
    const torch::Tensor total = pix.sum({1, 2});                                       // [Z]
    // Energy bookkeeping (Parseval): window energy / energy through the aperture.
    //   window = p² Σ_pix I_pix · δ⁴/(λs)²,  aperture = δ² Σ A²
    const double scale = std::pow(s.pixel_pitch_m * s.doe_pitch_m / (lambda * s.sensor_distance_m), 2) / aperture_energy_;
    energies.push_back(total.detach().to(torch::kFloat64) * scale);
    psfs.push_back(pix / total.clamp_min(std::numeric_limits<float>::min()).view({Z, 1, 1}));
    if (on_band) on_band(int64_t(l));
  }
  PsfStack out;
  out.psf = torch::stack(psfs);                 // [L, Z, P, P]
  out.energy_in_window = torch::stack(energies);  // [L, Z]
  check_finite(out.psf, "PSF stack");
  return out;
}

}  // namespace hsd::optics
