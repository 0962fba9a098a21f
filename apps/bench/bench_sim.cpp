// hsd_bench sim: forward+backward (gradient w.r.t. the height map) of PSF
// simulation plus sensor image formation on one patch, measured side by side
// in one run for
//   * hsd: matrix-Fourier-transform PSFs of the occupied layers, bands summed in
//     the Fourier domain, leave-out (a 7-layer and a 1-layer scene);
//   * the baseline: one 2x zero-padded FFT per (λ, z) PSF with bilinear
//     resampling, and one FFT convolution per (λ, z);
//   * the floor: the bare batched matrix products and FFTs hsd's method needs
//     (forward, and the same products again for the backward pass), no autograd.
#include <cmath>
#include <cstdio>
#include <functional>

#include <torch/torch.h>

#include "bench/baseline_psf.h"
#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/error.h"
#include "common/log.h"
#include "common/text_format.h"
#include "optics/doe.h"
#include "optics/psf.h"
#include "optics/sensor_image.h"
#include "optics/spectrum.h"

namespace hsd::bench {

namespace {

double rel_l1_max(const torch::Tensor& a, const torch::Tensor& ref) {
  return ((a.to(torch::kFloat64) - ref).abs().sum({2, 3}) / ref.abs().sum({2, 3})).max().item<double>();
}

// The matrix products and FFTs of one forward+backward of hsd's method, as bare
// batched ops on inputs made beforehand (so the floor times no allocation of inputs).
struct FloorWork {
  std::vector<torch::Tensor> kernels;  // per band [Z, r, N] (r = the kernel's rank, M when exact)
  std::vector<torch::Tensor> lefts;    // per band [M, r] (undefined when exact)
  std::vector<torch::Tensor> bases;    // per band [R, N] with the joint depth basis (then kernels/lefts are empty)
  std::vector<torch::Tensor> depth_lefts;  // per band [Z, M, R]
  torch::Tensor field, image, psf, ew, eh, image_grad;
  int64_t nh = 0, layers = 0;
  // depth_ranks: the joint depth basis's rank per band (optics/psf.h), empty without it.
  FloorWork(const optics::PsfSpec& spec, const std::vector<int64_t>& ranks, int64_t layers_, int64_t patch,
            const std::vector<int64_t>& depth_ranks = {})
      : layers(layers_) {
    const int64_t N = spec.doe_samples, P = spec.psf_size, r = P / 2, L = int64_t(spec.wavelengths_m.size());
    nh = fast_fft_size(patch + 2 * r);
    const auto c = torch::TensorOptions().dtype(torch::kComplexFloat);
    field = torch::randn({N, N}, c);
    // With the cross term of the cell integration the low-rank kernels carry G = 2 terms.
    const int64_t G = spec.cell_kernel_terms();
    for (size_t l = 0; l < depth_ranks.size(); ++l) {
      const int64_t M = P * spec.pixel_nodes[l / size_t(spec.spectral_samples)];
      bases.push_back(torch::randn({depth_ranks[l], N}, c));
      depth_lefts.push_back(torch::randn({layers, M, depth_ranks[l]}, c));
    }
    const size_t per_depth_bands = depth_ranks.empty() ? ranks.size() : 0;  // the joint basis replaces them
    for (size_t l = 0; l < per_depth_bands; ++l) {
      const int64_t M = P * spec.pixel_nodes[l / size_t(spec.spectral_samples)];
      const bool low = ranks[l] < M;
      kernels.push_back(torch::randn({layers, low ? G * ranks[l] : M, N}, c));
      lefts.push_back(low ? torch::randn({M, G * ranks[l]}, c) : torch::Tensor());
    }
    image = torch::randn({1, L, nh, nh});
    psf = torch::randn({L * layers * P, P}, c);     // the PSFs (as complex, as the method casts them)
    ew = torch::randn({P, nh / 2 + 1}, c);          // DFT matrices of the OTFs
    eh = torch::randn({nh, P}, c);
    image_grad = torch::randn({1, 3 * layers, nh, nh / 2 + 1}, c);
  }
  void run() const {
    const int64_t N = field.size(0);
    for (size_t l = 0; l < kernels.size(); ++l) {
      const torch::Tensor& k = kernels[l];
      const int64_t Z = k.size(0), M = k.size(1);
      const torch::Tensor b = torch::mm(k.view({Z * M, N}), field).view({Z, M, N});  // forward GEMM
      torch::Tensor f = torch::bmm(b, k.transpose(1, 2));                             // forward bmm
      if (lefts[l].defined()) {                                                       // low rank: L C Lᵀ and back
        const torch::Tensor full = torch::matmul(torch::matmul(lefts[l], f), lefts[l].t());
        f = torch::matmul(torch::matmul(lefts[l].t(), full), lefts[l]);
      }
      const torch::Tensor gb = torch::bmm(f, k);                                      // backward bmm
      torch::mm(k.view({Z * M, N}).t(), gb.view({Z * M, N}));                        // backward GEMM
    }
    for (size_t l = 0; l < bases.size(); ++l) {  // joint depth basis: F_z = L_z (B M Bᵀ) L_zᵀ and back
      const torch::Tensor &B = bases[l], &Lz = depth_lefts[l];
      const int64_t Z = Lz.size(0), M = Lz.size(1), R = Lz.size(2);
      const torch::Tensor y = torch::mm(torch::mm(B, field), B.t());
      const torch::Tensor f = torch::bmm(torch::mm(Lz.view({Z * M, R}), y).view({Z, M, R}), Lz.transpose(1, 2));
      const torch::Tensor gy = torch::mm(Lz.view({Z * M, R}).t(), torch::bmm(f, Lz).view({Z * M, R}));
      torch::mm(B.t(), torch::mm(gy, B));
    }
    torch::fft::rfft2(image);                                                         // band FFTs
    const int64_t P = psf.size(1), LZ = psf.size(0) / P, nwr = ew.size(1);
    const torch::Tensor t = torch::mm(psf, ew).view({LZ, P, nwr});                    // OTFs: E_h K E_wᵀ
    const torch::Tensor otf = torch::mm(eh, t.permute({1, 0, 2}).reshape({P, LZ * nwr}));
    torch::mm(eh.t(), otf);                                                           // their backward
    torch::mm(psf, ew);
    const torch::Tensor out = torch::fft::irfft2(image_grad, c10::IntArrayRef{nh, nh});  // 3 inverse FFTs per layer
    torch::fft::rfft2(out);                                                           // their backward
  }
};

struct SimArgs {
  int64_t patch = 256, bands = 25, depths = 7, psf = 0, pupil = 0;
  int repeats = 3;
  bool baseline = true;
};

SimArgs parse_sim_args(const Config& cfg, const AppArgs& args) {
  SimArgs a;
  a.patch = args.integer("--patch", 256), a.bands = args.integer("--bands", 25), a.depths = args.integer("--depths", 7);
  a.psf = args.integer("--psf", cfg.optics.psf_size), a.pupil = args.integer("--pupil", cfg.optics.doe_samples);
  a.repeats = int(args.integer("--repeats", 3));
  a.baseline = !args.has("--no-baseline");
  if (a.patch < 8 || a.patch > 4096) input_error("--patch", "must be in [8, 4096]");
  if (a.bands < 1 || a.bands > 200) input_error("--bands", "must be in [1, 200]");
  if (a.depths < 1 || a.depths > 64) input_error("--depths", "must be in [1, 64]");
  if (a.psf < 1 || a.psf % 2 == 0 || a.psf > a.patch) input_error("--psf", "must be odd and at most --patch");
  if (a.pupil < 16 || a.pupil > 8192) input_error("--pupil", "must be in [16, 8192]");
  return a;
}

// The benchmark's optics: bands spread over the config's range, depths linear
// in inverse depth over its range; the DOE grid keeps its physical size
// (pitch = grid / pupil); one PSF at each band centre (the baseline's model;
// hsd_bench accuracy measures spectral samples).
void resize_optics(OpticsConfig& o, const SimArgs& a) {
  const double lo = o.wavelengths_nm.front(), hi = o.wavelengths_nm.back();
  o.wavelengths_nm.clear();
  for (int64_t i = 0; i < a.bands; ++i)
    o.wavelengths_nm.push_back(a.bands == 1 ? lo : lo + (hi - lo) * double(i) / double(a.bands - 1));
  if (a.bands > 1) o.band_width_nm = (hi - lo) / double(a.bands - 1);
  double zmin = 1e300, zmax = 0.0;
  for (double z : o.depths_m) zmin = std::min(zmin, z), zmax = std::max(zmax, z);
  o.depths_m.clear();
  for (int64_t i = 0; i < a.depths; ++i)
    o.depths_m.push_back(1.0 / (1.0 / zmin + (1.0 / zmax - 1.0 / zmin) * (a.depths == 1 ? 0.0 : double(i) / double(a.depths - 1))));
  const double grid = double(o.doe_samples) * o.doe_pitch_m;
  if (a.pupil != o.doe_samples && (o.doe.init == DoeFamily::fisher || o.doe.init == DoeFamily::file))
    o.doe.init = DoeFamily::fresnel;  // a design file holds the config's grid; the timings do not depend on the heights
  o.doe_samples = a.pupil;
  o.doe_pitch_m = grid / double(a.pupil);
  o.psf_size = a.psf;
  o.spectral_samples = 1;
}

struct SimFigures {
  double rss_start = 0, t_all = 0, peak_all = 0, t_one = 0, t_floor = 0, t_joint = 0, t_joint_floor = 0;
  double t_base = 0, peak_base = 0, err_hsd = 0, err_base = 0, err_joint = 0;
  std::vector<int> pixel_nodes;
  std::vector<int64_t> kernel_ranks, depth_basis_ranks;
};

Json sim_json(const SimArgs& a, const SimFigures& f) {
  Json j{{"bench", "sim"},
         {"threads", torch::get_num_threads()},
         {"patch", a.patch},
         {"bands", a.bands},
         {"depths", a.depths},
         {"psf", a.psf},
         {"pupil", a.pupil},
         {"repeats", a.repeats},
         {"pixel_nodes", f.pixel_nodes},
         {"kernel_ranks", f.kernel_ranks},
         {"seconds_fwd_bwd", f.t_all},
         {"seconds_fwd_bwd_one_layer", f.t_one},
         {"one_layer_speedup", f.t_all / f.t_one},
         {"peak_rss_mib", f.peak_all},
         {"rss_at_start_mib", f.rss_start},
         {"seconds_floor", f.t_floor},
         {"ratio_to_floor", f.t_all / f.t_floor},
         {"psf_rel_l1_max", f.err_hsd},
         {"depth_basis_ranks", f.depth_basis_ranks},
         {"depth_basis_seconds_fwd_bwd", f.t_joint},
         {"depth_basis_seconds_floor", f.t_joint_floor},
         {"depth_basis_ratio_to_floor", f.t_joint / f.t_joint_floor},
         {"depth_basis_psf_rel_l1_max", f.err_joint}};
  if (a.baseline) {
    j["baseline_seconds_fwd_bwd"] = f.t_base;
    j["baseline_peak_rss_mib"] = f.peak_base;
    j["baseline_psf_rel_l1_max"] = f.err_base;
    j["speedup_vs_baseline"] = f.t_base / f.t_all;
    j["memory_ratio_vs_baseline"] = (f.peak_base - f.rss_start) / std::max(1.0, f.peak_all - f.rss_start);
  }
  return j;
}

std::string sim_text(const SimArgs& a, const SimFigures& f) {
  std::string text = "sensor simulation fwd+bwd: patch " + std::to_string(a.patch) + ", " + std::to_string(a.bands) +
                     " bands, " + std::to_string(a.depths) + " depths, PSF " + std::to_string(a.psf) + ", pupil " +
                     std::to_string(a.pupil) + ", threads " + std::to_string(torch::get_num_threads()) + "\n";
  text += format("process RSS before the runs: %.0f MiB\n", f.rss_start);
  text += "method                               fwd+bwd [s]  peak RSS [MiB]  PSF rel L1 worst\n";
  text += format("%-36s %11.3f %15.0f %17.2e\n", ("hsd, " + std::to_string(a.depths) + "-layer scene").c_str(), f.t_all,
                 f.peak_all, f.err_hsd);
  text += format("%-36s %11.3f\n", "hsd, 1-layer scene", f.t_one);
  text += format("%-36s %11.3f\n", "floor (bare GEMMs and FFTs)", f.t_floor);
  text += format("%-36s %11.3f %15s %17.2e\n", "hsd, joint depth basis (training)", f.t_joint, "", f.err_joint);
  text += format("%-36s %11.3f\n", "its floor (bare GEMMs and FFTs)", f.t_joint_floor);
  text += format("joint depth basis: %.2fx faster than per depth, %.2fx its floor\n", f.t_all / f.t_joint,
                 f.t_joint / f.t_joint_floor);
  if (a.baseline) {
    text += format("%-36s %11.3f %15.0f %17.2e\n", "baseline (FFT PSF + per-(l,z) conv)", f.t_base, f.peak_base, f.err_base);
    text += format("speed-up vs baseline %.1fx, memory (above start) %.1fx less, 1-layer %.1fx faster, %.2fx the floor\n",
                   f.t_base / f.t_all, (f.peak_base - f.rss_start) / std::max(1.0, f.peak_all - f.rss_start),
                   f.t_all / f.t_one, f.t_all / f.t_floor);
  }
  return text;
}

}  // namespace

int bench_sim(Config cfg, const AppArgs& args, BenchOutput& out) {
  const SimArgs a = parse_sim_args(cfg, args);
  auto& o = cfg.optics;
  resize_optics(o, a);
  const int64_t patch = a.patch, depths = a.depths;
  const auto material = optics::Material::load(o.material);
  const auto spec = optics::make_psf_spec(o, material, torch::kCPU);
  const optics::PsfSimulator sim(spec);
  const torch::Tensor h0 = optics::make_doe(o, material, cfg.seed, torch::kCPU).height().detach();
  const torch::Tensor omega = optics::camera_response(cfg.sensor.camera, spec.wavelengths_m, o.band_width_m());
  torch::manual_seed(int64_t(cfg.seed));
  const torch::Tensor radiance = torch::rand({1, a.bands, patch, patch});
  // 7-layer scene: vertical stripes, one per layer; 1-layer scene: the middle layer.
  torch::Tensor depth_all = torch::empty({1, 1, patch, patch});
  for (int64_t z = 0; z < depths; ++z)
    depth_all.narrow(3, z * patch / depths, (z + 1) * patch / depths - z * patch / depths).fill_(o.depths_m[size_t(z)]);
  const torch::Tensor depth_one = torch::full({1, 1, patch, patch}, o.depths_m[size_t(depths / 2)]);
  const torch::Tensor weights = torch::rand({1, 3, patch, patch});
  // One forward+backward into the height map: the PSFs of the scene's layers
  // (of every layer unless occupied_only) through psf_of, then the sensor
  // image (the baseline's direct convolution when direct).
  using PsfOf = std::function<torch::Tensor(const torch::Tensor& h, const std::vector<int64_t>& layers)>;
  std::vector<int64_t> every_layer;
  for (int64_t z = 0; z < depths; ++z) every_layer.push_back(z);
  auto fwd_bwd = [&](const PsfOf& psf_of, const torch::Tensor& depth, bool occupied_only, bool direct) {
    return [&, psf_of, depth, occupied_only, direct] {
      torch::Tensor h = h0.clone().set_requires_grad(true);
      const auto layers = occupied_only ? optics::occupied_layers(depth, spec.depths_m) : every_layer;
      std::vector<double> ld;
      for (int64_t z : layers) ld.push_back(spec.depths_m[size_t(z)]);
      const torch::Tensor p = psf_of(h, layers).to(torch::kFloat32);
      const torch::Tensor masks = optics::layer_masks(depth, ld, 1.0);
      const torch::Tensor J = direct ? optics::render_sensor_image_direct(radiance, masks, p, omega)
                                     : optics::render_sensor_image(radiance, masks, p, omega);
      (J * weights).sum().backward();
    };
  };
  const PsfOf hsd_psf = [&](const torch::Tensor& h, const std::vector<int64_t>& layers) { return sim.compute(h, layers).psf; };
  const torch::Tensor aperture = sim.aperture();
  SimFigures f;
  f.pixel_nodes = spec.pixel_nodes, f.kernel_ranks = sim.kernel_ranks();
  f.rss_start = current_rss_mib();
  log::info("hsd, " + std::to_string(depths) + "-layer scene ...");
  f.t_all = median_seconds(fwd_bwd(hsd_psf, depth_all, true, false), a.repeats);
  f.peak_all = peak_rss_during(fwd_bwd(hsd_psf, depth_all, true, false));
  log::info("hsd, 1-layer scene ...");
  f.t_one = median_seconds(fwd_bwd(hsd_psf, depth_one, true, false), a.repeats);
  log::info("floor (bare matrix products and FFTs) ...");
  const FloorWork floor(spec, sim.kernel_ranks(), depths, patch);
  f.t_floor = median_seconds([&] { floor.run(); }, a.repeats);
  // The training's simulator: the same PSFs through the joint depth basis (psf.h), and its own floor.
  auto joint_spec = spec;
  joint_spec.depth_basis = true;
  const optics::PsfSimulator joint_sim(joint_spec);
  const auto joint_step =
      fwd_bwd([&](const torch::Tensor& h, const std::vector<int64_t>&) { return joint_sim.compute(h).psf; }, depth_all, false, false);
  log::info("hsd with the joint depth basis (as in training), " + std::to_string(depths) + "-layer scene ...");
  joint_step();  // builds the basis (once per simulator; not part of a step)
  f.t_joint = median_seconds(joint_step, a.repeats);
  f.depth_basis_ranks = joint_sim.depth_basis_ranks();
  const FloorWork joint_floor(spec, sim.kernel_ranks(), depths, patch, joint_sim.depth_basis_ranks());
  f.t_joint_floor = median_seconds([&] { joint_floor.run(); }, a.repeats);
  if (a.baseline) {
    log::info("baseline (FFT + bilinear PSFs, one FFT convolution per (lambda, z)) ...");
    const auto baseline_step =
        fwd_bwd([&](const torch::Tensor& h, const std::vector<int64_t>&) { return baseline_fft_psf(spec, aperture, h); },
                depth_all, false, true);
    f.t_base = median_seconds(baseline_step, std::max(1, a.repeats / 2));
    f.peak_base = peak_rss_during(baseline_step);
  }
  log::info("PSF accuracy against float64 with 8x8 nodes per pixel ...");
  {
    torch::NoGradGuard g;
    const torch::Tensor ref = optics::PsfSimulator(optics::converged_reference(spec)).compute(h0).psf;
    f.err_hsd = rel_l1_max(sim.compute(h0).psf, ref);
    f.err_joint = rel_l1_max(joint_sim.compute(h0).psf, ref);
    if (a.baseline) f.err_base = rel_l1_max(baseline_fft_psf(spec, aperture, h0), ref);
  }
  out.json = sim_json(a, f);
  out.text = sim_text(a, f);
  return 0;
}

}  // namespace hsd::bench
