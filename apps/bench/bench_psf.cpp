// hsd_bench psf: time and peak memory of the whole PSF stack (all bands and
// depths of the config), forward and forward+backward (gradient w.r.t. the
// height map), and its error against a converged float64 computation; the same
// for the straightforward FFT + bilinear baseline and for point-sampled pixels,
// measured side by side in one run.
#include <cstdio>

#include <torch/torch.h>

#include "bench/baseline_psf.h"
#include "bench/bench_util.h"
#include "bench/benches.h"
#include "common/log.h"
#include "common/text_format.h"
#include "optics/doe.h"
#include "optics/psf.h"

namespace hsd::bench {

namespace {

struct Measured {
  double fwd_s = 0, fwd_bwd_s = 0, peak_fwd_bwd_mib = 0, rel_l1_mean = 0, rel_l1_max = 0;
};

Json to_json(const Measured& m) {
  return Json{{"seconds_fwd", m.fwd_s}, {"seconds_fwd_bwd", m.fwd_bwd_s}, {"peak_rss_fwd_bwd_mib", m.peak_fwd_bwd_mib},
              {"psf_rel_l1_mean", m.rel_l1_mean}, {"psf_rel_l1_max", m.rel_l1_max}};
}

// f(h) -> psf [L, Z, P, P]
Measured measure(const std::function<torch::Tensor(const torch::Tensor&)>& f, const torch::Tensor& h,
                 const torch::Tensor& ref, int repeats) {
  Measured m;
  m.fwd_s = median_seconds([&] { torch::NoGradGuard g; f(h); }, repeats);
  const torch::Tensor w = torch::rand(ref.sizes(), torch::TensorOptions().dtype(torch::kFloat32));
  auto fwd_bwd = [&] {
    torch::Tensor hp = h.detach().clone().set_requires_grad(true);
    (f(hp) * w.to(hp.device())).sum().backward();
  };
  m.fwd_bwd_s = median_seconds(fwd_bwd, repeats);
  m.peak_fwd_bwd_mib = peak_rss_during(fwd_bwd);
  torch::NoGradGuard g;
  const torch::Tensor err = (f(h).to(torch::kFloat64).cpu() - ref).abs().sum({2, 3}) / ref.abs().sum({2, 3});
  m.rel_l1_mean = err.mean().item<double>();
  m.rel_l1_max = err.max().item<double>();
  return m;
}

// The table printed: one row per method measured (a null entry is skipped).
std::string psf_text(const optics::PsfSpec& spec, FloatPrecision precision, double rss_start,
                     const std::vector<std::pair<const char*, const Measured*>>& rows) {
  std::string text = "PSF stack: " + std::to_string(spec.wavelengths_m.size()) + " bands x " +
                     std::to_string(spec.depths_m.size()) + " depths, " + std::to_string(spec.psf_size) + " px window, " +
                     std::to_string(spec.doe_samples) + "^2 DOE samples, " + choice_name(precision) + ", threads " +
                     std::to_string(torch::get_num_threads()) + "\n";
  text += format("process RSS before the runs: %.0f MiB (LibTorch and data); peak RSS below includes it\n", rss_start);
  text += "method                          fwd [s]  fwd+bwd [s]  peak RSS [MiB]  rel L1 mean  rel L1 worst\n";
  for (const auto& [name, m] : rows)
    if (m)
      text += format("%-30s %8.3f %12.3f %15.0f %12.2e %13.2e\n", name, m->fwd_s, m->fwd_bwd_s, m->peak_fwd_bwd_mib,
                     m->rel_l1_mean, m->rel_l1_max);
  return text;
}

}  // namespace

int bench_psf(const Config& cfg, const AppArgs& args, BenchOutput& out) {
  const int repeats = int(args.integer("--repeats", 3));
  const auto material = optics::Material::load(cfg.optics.material);
  // The baseline's model: one PSF at each band centre (hsd_bench accuracy measures spectral samples).
  OpticsConfig optics_cfg = cfg.optics;
  optics_cfg.spectral_samples = 1;
  const auto spec = optics::make_psf_spec(optics_cfg, material, torch::kCPU);
  const torch::Tensor h = optics::make_doe(cfg.optics, material, cfg.seed, torch::kCPU).height().detach();
  const double rss_start = current_rss_mib();

  // Converged reference: float64, 8 Gauss nodes per pixel axis.
  const auto ref_spec = optics::converged_reference(spec);
  torch::Tensor ref;
  {
    torch::NoGradGuard g;
    log::info("reference (float64, 8x8 nodes per pixel) ...");
    ref = optics::PsfSimulator(ref_spec).compute(h).psf;
  }

  const optics::PsfSimulator sim(spec);  // spec.recompute_in_backward as configured (default: store)
  log::info("hsd (matrix Fourier transform, Gauss nodes per band) ...");
  const Measured ours = measure([&](const torch::Tensor& hh) { return sim.compute(hh).psf; }, h, ref, repeats);

  auto lean_spec = spec;
  lean_spec.recompute_in_backward = true;
  const optics::PsfSimulator lean_sim(lean_spec);
  log::info("hsd recomputing each band in the backward pass ...");
  const Measured lean = measure([&](const torch::Tensor& hh) { return lean_sim.compute(hh).psf; }, h, ref, repeats);

  auto point_spec = spec;
  point_spec.pixel_nodes.assign(spec.pixel_nodes.size(), 1);
  const optics::PsfSimulator point_sim(point_spec);
  log::info("hsd with point-sampled pixels ...");
  const Measured point = measure([&](const torch::Tensor& hh) { return point_sim.compute(hh).psf; }, h, ref, repeats);

  Measured base;
  if (!args.has("--no-baseline")) {
    log::info("baseline (2x zero-padded FFT per (lambda, z), bilinear resampling, point-sampled pixels) ...");
    base = measure([&](const torch::Tensor& hh) { return baseline_fft_psf(spec, sim.aperture(), hh); }, h, ref,
                   std::max(1, repeats / 2));
  }

  std::vector<int> nodes = spec.pixel_nodes;
  out.json = Json{{"bench", "psf"},
                  {"threads", torch::get_num_threads()},
                  {"bands", spec.wavelengths_m.size()},
                  {"depths", spec.depths_m.size()},
                  {"psf_size", spec.psf_size},
                  {"doe_samples", spec.doe_samples},
                  {"precision", choice_name(cfg.optics.precision)},
                  {"doe_init", choice_word(cfg.optics.doe.init, cfg.optics.doe.init_path)},
                  {"pixel_nodes", nodes},
                  {"rss_at_start_mib", rss_start},
                  {"hsd", to_json(ours)},
                  {"hsd_recompute_backward", to_json(lean)},
                  {"hsd_point_sampled", to_json(point)}};
  if (!args.has("--no-baseline")) out.json["baseline_fft_bilinear"] = to_json(base);
  // Flat keys for scripts (the contract's style).
  out.json["seconds_fwd"] = ours.fwd_s;
  out.json["seconds_fwd_bwd"] = ours.fwd_bwd_s;
  out.json["peak_rss_mib"] = ours.peak_fwd_bwd_mib;
  out.json["peak_rss_increase_mib"] = ours.peak_fwd_bwd_mib - rss_start;
  out.json["psf_rel_l1_mean"] = ours.rel_l1_mean;
  out.json["psf_rel_l1_max"] = ours.rel_l1_max;

  out.text = psf_text(spec, cfg.optics.precision, rss_start,
                      {{"hsd (MFT, Gauss pixels)", &ours}, {"hsd, recompute in backward", &lean},
                       {"hsd, point-sampled pixels", &point}, {"baseline FFT + bilinear", args.has("--no-baseline") ? nullptr : &base}});
  return 0;
}

}  // namespace hsd::bench
