#include "optics/psf.h"

#include <cmath>
#include <mutex>

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
  s.real_dtype = cfg.precision == FloatPrecision::float64 ? torch::kFloat64 : torch::kFloat32;
  s.device = device;
  s.recompute_in_backward = cfg.psf_backward == PsfBackward::recompute;
  s.mft_rank_tol = cfg.mft_rank_tol;
  s.pupil_oversampling = cfg.pupil_oversampling;
  s.pupil_cell_integration = cfg.pupil_cell_integration;
  s.spectral_samples = cfg.spectral_samples;
  s.band_width_m = cfg.band_width_m();
  if (s.spectral_samples > 1) s.spectral_refractive_index = material.indices(s.spectral_wavelengths_m());
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

PsfSpec converged_reference(const PsfSpec& spec) {
  PsfSpec r = spec;
  r.real_dtype = torch::kFloat64;
  r.pixel_nodes.assign(spec.pixel_nodes.size(), 8);
  r.mft_rank_tol = 0.0;
  return r;
}

double PsfSpec::resolved_band_width_m() const {
  if (band_width_m > 0.0) return band_width_m;
  if (wavelengths_m.size() < 2) return 10e-9;
  return (wavelengths_m.back() - wavelengths_m.front()) / double(wavelengths_m.size() - 1);
}

std::vector<double> PsfSpec::spectral_wavelengths_m() const {
  const Quadrature1D q = gauss_legendre(int(spectral_samples));
  const double w = resolved_band_width_m();
  std::vector<double> out;
  for (double c : wavelengths_m)
    for (double u : q.nodes) out.push_back(c + (spectral_samples > 1 ? w * u : 0.0));
  return out;
}

std::vector<double> PsfSpec::spectral_weights() const {
  const Quadrature1D q = gauss_legendre(int(spectral_samples));
  std::vector<double> out;
  for (size_t l = 0; l < wavelengths_m.size(); ++l) out.insert(out.end(), q.weights.begin(), q.weights.end());
  return out;
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
  if (s.pupil_oversampling < 1) throw InputError("PSF: pupil_oversampling must be >= 1");
  if (s.spectral_samples < 1) throw InputError("PSF: spectral_samples must be >= 1");
  const size_t K = size_t(s.spectral_samples);
  if (!(s.band_width_m >= 0.0)) throw InputError("PSF: band_width_m must be >= 0 (0 = the wavelengths' spacing)");
  if (K > 1 && s.spectral_refractive_index.size() != L * K)
    throw InputError("PSF: spectral_samples = " + std::to_string(K) + " needs spectral_refractive_index with " + std::to_string(L * K) +
                     " entries (bands x spectral_samples; make_psf_spec fills it from the material), or spectral_samples = 1");
  node_wavelength_m_ = s.spectral_wavelengths_m();
  node_weight_ = s.spectral_weights();
  node_index_ = K > 1 ? s.spectral_refractive_index : s.refractive_index;
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(s.device);
  aperture_ = aperture_transmission(s.pupil_samples(), s.pupil_pitch_m(), s.aperture_diameter_m, s.aperture_shape).to(f64);
  aperture_energy_ = aperture_.pow(2).sum().item<double>();
  aperture_real_ = aperture_.to(s.real_dtype);
  if (!(aperture_energy_ > 0.0)) throw InputError("PSF: the aperture covers no DOE sample");
  pupil_x_ = centred_coordinates(s.pupil_samples(), s.pupil_pitch_m()).to(f64);
  kernels_ = std::make_shared<KernelCache>(L * K);
}

namespace {

// The pupil factors of one wavelength's kernels for each depth: the defocus
// chirp with its cell integration (fresnel_mft.h). [Z, 2, N] with the cross
// term (sinc(A) on the main term, −sinc'(A) on the cross term), else [Z, N].
torch::Tensor depth_chirps(const torch::Tensor& pupil_x, double wavelength_m, const std::vector<double>& depths_m,
                           double sensor_distance_m, double cell_m, bool cell_sinc, bool cross, c10::ScalarType cdt) {
  const auto real = c10::toRealValueType(cdt);
  std::vector<torch::Tensor> chirps;
  for (double z : depths_m) {
    const torch::Tensor c = compute_defocus_chirp(pupil_x, wavelength_m, z, sensor_distance_m, cdt);
    const double k = 2.0 * M_PI / wavelength_m, curvature = 1.0 / z + 1.0 / sensor_distance_m;
    const torch::Tensor slope = pupil_x * (k * curvature);  // the chirp's slope across each cell
    if (cross) {
      chirps.push_back(torch::stack({c * cell_average_factor(slope, cell_m).to(real),
                                     c * cell_cross_factor(slope, cell_m).to(real)}));
    } else {
      chirps.push_back(cell_sinc ? c * cell_average_factor(slope, cell_m).to(real) : c);
    }
  }
  return torch::stack(chirps);
}

}  // namespace

// Node j's kernels, built on first use (once, whichever thread asks first): a
// scene or a batch that leaves out bands never pays for their factorisations.
const PsfSimulator::NodeKernel& PsfSimulator::kernel(size_t j) const {
  KernelCache& c = *kernels_;
  std::call_once(c.once[j], [&] { c.kernels[j] = build_kernel(j); });
  return c.kernels[j];
}

PsfSimulator::NodeKernel PsfSimulator::build_kernel(size_t j) const {
  const auto& s = spec_;
  const size_t K = size_t(s.spectral_samples);
  const bool cell_sinc = s.cell_sinc(), cross = s.cell_kernel_terms() == 2;
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64).device(s.device);
  const torch::Tensor pixel_x = centred_coordinates(s.psf_size, s.pixel_pitch_m);  // [P]
  const auto cdt = complex_dtype();
  NodeKernel out;
  {
    const Quadrature1D q = gauss_legendre(s.pixel_nodes[j / K]);
    const torch::Tensor nodes = torch::tensor(q.nodes, torch::kFloat64) * s.pixel_pitch_m;    // [n]
    const torch::Tensor sensor_x = (pixel_x.view({-1, 1}) + nodes.view({1, -1})).reshape(-1);  // [P·n], pixel-major
    const torch::Tensor tilt64 =
        compute_tilt_kernel(sensor_x.to(f64), pupil_x_, node_wavelength_m_[j], s.sensor_distance_m, torch::kComplexDouble);
    // Cell integration (fresnel_mft.h): the tilt's slope k x/s across each cell
    // gives a factor per sensor point (row): sinc(B) on the main term, B on the
    // cross term (whose pupil factor goes with the chirps).
    const torch::Tensor slope = sensor_x.to(f64) * (2.0 * M_PI / node_wavelength_m_[j] / s.sensor_distance_m);
    const torch::Tensor row0 = cell_sinc ? cell_average_factor(slope, s.pupil_pitch_m()) : torch::ones_like(slope);
    const torch::Tensor row1 = slope * (0.5 * s.pupil_pitch_m());  // B
    auto rows = [](const torch::Tensor& m, const torch::Tensor& f) { return m * f.view({-1, 1}).to(m.scalar_type()); };
    if (s.mft_rank_tol > 0.0) {
      const LowRankKernel k = factor_tilt_kernel(tilt64, s.mft_rank_tol, torch::kComplexDouble);
      const torch::Tensor left = cross ? torch::cat({rows(k.left, row0), rows(k.left, row1)}, 1) : rows(k.left, row0);
      out.left = left.to(cdt).contiguous();
      out.right = k.right.to(cdt).contiguous();
      if (s.depth_basis) {
        // K_z = Σ_g left_g (right ⊙ chirp_z,g) for every configured depth, in complex128.
        const torch::Tensor c = depth_chirps(pupil_x_, node_wavelength_m_[j], s.depths_m, s.sensor_distance_m,
                                             s.pupil_pitch_m(), cell_sinc, cross, torch::kComplexDouble);
        // W_z = [right ⊙ chirp_z,g]_g as [G·r, Z·N]; then all K_z = left · W_z in one product.
        const torch::Tensor cz = cross ? c : c.unsqueeze(1);                                  // [Z, G, N]
        const int64_t Z = cz.size(0), G = cz.size(1), r = k.right.size(0), N = k.right.size(1);
        const torch::Tensor W = (k.right.view({1, 1, r, N}) * cz.unsqueeze(2)).permute({1, 2, 0, 3}).reshape({G * r, Z * N});
        const torch::Tensor kz = torch::mm(left, W).view({left.size(0), Z, N}).permute({1, 0, 2});  // [Z, M, N]
        const DepthBasis d = factor_depth_kernels(kz, s.mft_rank_tol, cdt);
        out.depth_left = d.left, out.depth_basis = d.basis;
      }
    } else {
      out.tilt = (cross ? torch::stack({rows(tilt64, row0), rows(tilt64, row1)}) : rows(tilt64, row0)).to(cdt);
    }
    const torch::Tensor w = torch::tensor(q.weights, torch::kFloat64);
    out.weights = w.to(torch::TensorOptions().dtype(s.real_dtype).device(s.device));
  }
  return out;
}

namespace {

// Everything one band's PSF needs, by value (tensors are shared, not copied), so
// a recomputation in the backward pass does not depend on the simulator object
// still being alive.
struct BandContext {
  torch::Tensor aperture, tilt, left, right, weights, pupil_x;  // left/right undefined: exact MFT
  torch::Tensor depth_left, depth_basis;  // the joint depth basis (undefined: per depth); depth_left holds the requested depths
  double wavelength_m = 0, refractive_index = 0, sensor_distance_m = 0, pixel_pitch_m = 0, doe_pitch_m = 0,
         aperture_energy = 0;
  int64_t psf_size = 0, nodes = 0;
  bool cell_sinc = true;  // chirps integrated across each pupil cell (cell_average_factor)
  bool cross = false;     // plus the cross term: a second kernel term (G = 2)
  c10::ScalarType complex_dtype = torch::kComplexFloat;
  std::vector<double> depths_m;

  void save(torch::autograd::AutogradContext* ctx) const {
    auto& d = ctx->saved_data;
    d["aperture"] = aperture;
    d["tilt"] = tilt;
    d["left"] = left;
    d["right"] = right;
    d["weights"] = weights;
    d["depth_left"] = depth_left;
    d["depth_basis"] = depth_basis;
    d["pupil_x"] = pupil_x;
    d["scalars"] = c10::List<double>({wavelength_m, refractive_index, sensor_distance_m, pixel_pitch_m, doe_pitch_m,
                                      aperture_energy});
    d["ints"] = c10::List<int64_t>({psf_size, nodes, int64_t(complex_dtype), int64_t(cell_sinc), int64_t(cross)});
    d["depths"] = c10::List<double>(depths_m);
  }
  static BandContext load(torch::autograd::AutogradContext* ctx) {
    auto& d = ctx->saved_data;
    BandContext b;
    b.aperture = d["aperture"].toTensor();
    if (d["tilt"].isTensor()) b.tilt = d["tilt"].toTensor();
    if (d["left"].isTensor()) b.left = d["left"].toTensor();
    if (d["right"].isTensor()) b.right = d["right"].toTensor();
    b.weights = d["weights"].toTensor();
    if (d["depth_left"].isTensor()) b.depth_left = d["depth_left"].toTensor();
    if (d["depth_basis"].isTensor()) b.depth_basis = d["depth_basis"].toTensor();
    b.pupil_x = d["pupil_x"].toTensor();
    const auto sc = d["scalars"].toDoubleVector();
    b.wavelength_m = sc[0], b.refractive_index = sc[1], b.sensor_distance_m = sc[2], b.pixel_pitch_m = sc[3],
    b.doe_pitch_m = sc[4], b.aperture_energy = sc[5];
    const auto in = d["ints"].toIntVector();
    b.psf_size = in[0], b.nodes = in[1], b.complex_dtype = c10::ScalarType(in[2]), b.cell_sinc = in[3] != 0, b.cross = in[4] != 0;
    b.depths_m = d["depths"].toDoubleVector();
    return b;
  }
};

// One band: normalised PSFs [Z, P, P] and energy_in_window [Z] (no grad).
std::pair<torch::Tensor, torch::Tensor> band_psf(const BandContext& b, const torch::Tensor& h) {
  const int64_t P = b.psf_size, n = b.nodes, Z = int64_t(b.depths_m.size());
  const torch::Tensor field = compute_pupil_field(b.aperture, h, b.wavelength_m, b.refractive_index, b.complex_dtype);
  // |K_z M K_zᵀ|² with K_z = tilt ⊙ chirp_z: [Z, P·n, P·n]; the kernels are rebuilt in backward, not stored.
  torch::Tensor I;
  if (b.depth_basis.defined()) {
    I = mft_intensity_depth_basis({b.depth_left, b.depth_basis}, field);
  } else {
    const torch::Tensor chirps = depth_chirps(b.pupil_x, b.wavelength_m, b.depths_m, b.sensor_distance_m, b.doe_pitch_m,
                                              b.cell_sinc, b.cross, b.complex_dtype);
    I = b.left.defined() ? mft_intensity_low_rank({b.left, b.right}, chirps, field) : mft_intensity(b.tilt, chirps, field);
  }
  // Pixel integral: Gauss–Legendre weights over each pixel's n×n nodes, one
  // axis at a time (a product over the contiguous axis, then over rows).
  const torch::Tensor cols = torch::mv(I.reshape({-1, n}), b.weights).view({Z * P, n, P});  // Σ_j w_j I[.., j]
  const torch::Tensor pix = (cols * b.weights.view({1, n, 1})).sum(1).view({Z, P, P});        // [Z, P, P]
  const torch::Tensor total = pix.sum({1, 2});                                  // [Z]
  // Energy bookkeeping (Parseval): window energy / energy through the aperture.
  //   window = p² Σ_pix I_pix · δ⁴/(λs)²,  aperture = δ² Σ A²
  const double scale =
      std::pow(b.pixel_pitch_m * b.doe_pitch_m / (b.wavelength_m * b.sensor_distance_m), 2) / b.aperture_energy;
  const torch::Tensor energy = total.detach().to(torch::kFloat64) * scale;
  const torch::Tensor psf = pix / total.clamp_min(std::numeric_limits<float>::min()).view({Z, 1, 1});
  return {psf, energy};
}

// Checkpointed band: forward without a graph; backward recomputes the band
// with a graph and differentiates it. Stores the height map and shared constants.
struct RecomputedBand : public torch::autograd::Function<RecomputedBand> {
  static torch::autograd::variable_list forward(torch::autograd::AutogradContext* ctx, torch::Tensor height,
                                                const BandContext& band) {
    ctx->save_for_backward({height});
    band.save(ctx);
    torch::Tensor psf, energy;
    {
      torch::NoGradGuard no_grad;
      std::tie(psf, energy) = band_psf(band, height);
    }
    ctx->mark_non_differentiable({energy});
    return {psf, energy};
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const BandContext band = BandContext::load(ctx);
    const torch::Tensor h = ctx->get_saved_variables()[0].detach().requires_grad_(true);
    torch::Tensor g;
    {
      torch::AutoGradMode enable(true);
      const torch::Tensor psf = band_psf(band, h).first;
      g = torch::autograd::grad({psf}, {h}, {grads[0]})[0];
    }
    return {g, torch::Tensor()};
  }
};

}  // namespace

std::vector<int64_t> PsfSimulator::kernel_ranks() const {
  std::vector<int64_t> r;
  const int64_t G = spec_.cell_kernel_terms();
  for (size_t j = 0; j < kernels_->kernels.size(); ++j) {
    const NodeKernel& k = kernel(j);
    r.push_back(k.left.defined() ? k.left.size(1) / G : k.tilt.size(-2));
  }
  return r;
}

std::vector<int64_t> PsfSimulator::depth_basis_ranks() const {
  std::vector<int64_t> r;
  for (size_t j = 0; j < kernels_->kernels.size(); ++j) {
    const NodeKernel& k = kernel(j);
    r.push_back(k.depth_basis.defined() ? k.depth_basis.size(0) : 0);
  }
  return r;
}

PsfStack PsfSimulator::compute(const torch::Tensor& height_m, const std::vector<int64_t>& depth_indices,
                               const std::function<void(int64_t)>& on_band,
                               const std::vector<int64_t>& band_indices) const {
  const auto& s = spec_;
  const int64_t N = s.doe_samples, k = s.pupil_oversampling, K = s.spectral_samples;
  if (height_m.dim() != 2 || height_m.size(0) != N || height_m.size(1) != N)
    throw InputError("PSF: height map must be [" + std::to_string(N) + ", " + std::to_string(N) + "], got " +
                     c10::str(height_m.sizes()));
  std::vector<int64_t> zi = depth_indices;
  if (zi.empty())
    for (int64_t z = 0; z < int64_t(s.depths_m.size()); ++z) zi.push_back(z);
  for (int64_t z : zi)
    if (z < 0 || z >= int64_t(s.depths_m.size())) throw InputError("PSF: depth index out of range");
  std::vector<int64_t> li = band_indices;
  if (li.empty())
    for (int64_t l = 0; l < int64_t(s.wavelengths_m.size()); ++l) li.push_back(l);
  for (int64_t l : li)
    if (l < 0 || l >= int64_t(s.wavelengths_m.size())) throw InputError("PSF: band index out of range");
  check_finite(height_m, "DOE height map (input of the PSF simulator)");
  // Each DOE cell of constant height covers k×k pupil samples (differentiable copy).
  const torch::Tensor h = k == 1 ? height_m.to(s.device)
                                 : height_m.to(s.device).repeat_interleave(k, 0).repeat_interleave(k, 1);
  const bool checkpoint = s.recompute_in_backward && h.requires_grad() && torch::GradMode::is_enabled();

  BandContext b;
  b.aperture = aperture_real_, b.pupil_x = pupil_x_;
  b.sensor_distance_m = s.sensor_distance_m, b.pixel_pitch_m = s.pixel_pitch_m, b.doe_pitch_m = s.pupil_pitch_m();
  b.aperture_energy = aperture_energy_, b.psf_size = s.psf_size, b.complex_dtype = complex_dtype();
  b.cell_sinc = s.cell_sinc();
  b.cross = s.cell_kernel_terms() == 2;
  for (int64_t z : zi) b.depths_m.push_back(s.depths_m[size_t(z)]);
  bool all_depths = zi.size() == s.depths_m.size();
  for (size_t i = 0; i < zi.size() && all_depths; ++i) all_depths = zi[i] == int64_t(i);
  // The joint depth basis holds every configured depth; a subset picks its rows.
  const torch::Tensor zsel = s.depth_basis && !all_depths
                                 ? torch::tensor(zi, torch::TensorOptions().dtype(torch::kLong).device(s.device))
                                 : torch::Tensor();

  std::vector<torch::Tensor> psfs, energies;
  for (int64_t l : li) {
    torch::Tensor psf, energy;
    for (int64_t q = 0; q < K; ++q) {
      const size_t j = size_t(l * K + q);
      const NodeKernel& kj = kernel(j);
      b.tilt = kj.tilt, b.left = kj.left, b.right = kj.right, b.weights = kj.weights;
      b.depth_basis = kj.depth_basis;
      b.depth_left = kj.depth_left.defined() && zsel.defined() ? kj.depth_left.index_select(0, zsel) : kj.depth_left;
      b.wavelength_m = node_wavelength_m_[j], b.refractive_index = node_index_[j], b.nodes = s.pixel_nodes[size_t(l)];
      torch::Tensor p, e;
      if (checkpoint) {
        const auto r = RecomputedBand::apply(h, b);
        p = r[0], e = r[1];
      } else {
        std::tie(p, e) = band_psf(b, h);
      }
      if (K == 1) {
        psf = p, energy = e;
      } else {  // Σ_k w_k P(λ_k): each term sums to 1, so does the band's PSF
        psf = q == 0 ? p * node_weight_[j] : psf + p * node_weight_[j];
        energy = q == 0 ? e * node_weight_[j] : energy + e * node_weight_[j];
      }
    }
    psfs.push_back(psf);
    energies.push_back(energy);
    if (on_band) on_band(l);
  }
  PsfStack out;
  out.psf = torch::stack(psfs);                   // [L, Z, P, P]
  out.energy_in_window = torch::stack(energies);  // [L, Z]
  check_finite(out.psf, "PSF stack");
  return out;
}

}  // namespace hsd::optics
