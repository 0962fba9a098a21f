// hsd_fisher: the CRLB of the Fresnel and spiral DOEs and a Fisher-information
// design (optics/fisher.h, optics/fisher_design.h). Writes DIR/crlb.json
// (fresnel, spiral, fisher: aggregate and per-parameter CRLBs), DIR/crlb.md,
// DIR/fisher_height.pt (height-map file on the config's DOE grid, usable as
// optics.doe.init = "fisher" via optics.doe.fisher_path, or "file:PATH"),
// DIR/fisher_curve.png, DIR/psf_atlas_fisher.png and DIR/config.json.
#include <chrono>
#include <cstdio>
#include <tuple>

#include <torch/torch.h>

#include "common/app.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/text_format.h"
#include "optics/doe.h"
#include "optics/fisher.h"
#include "optics/fisher_design.h"
#include "optics/psf.h"
#include "optics/scene_fisher.h"
#include "optics/spectrum.h"
#include "viz/plot.h"
#include "viz/psf_atlas.h"
#include "usage/hsd_fisher.h"

using namespace hsd;

namespace {

const char* kUsage = usage::kText;

Json report_json(const optics::CrlbReport& r) {
  auto finite = [](double v) { return std::isfinite(v) ? Json(v) : Json("inf"); };
  Json cond = Json::array();
  for (int64_t i = 0; i < r.condition.numel(); ++i) cond.push_back(finite(r.condition.view(-1)[i].item<double>()));
  return Json{{"aggregate", r.aggregate.item<double>()},
              {"aggregate_capped_mean", r.aggregate_capped},
              {"aggregate_median", r.aggregate_median},
              {"aggregate_mean", r.aggregate_mean},
              {"condition_number", cond},
              {"mean_crlb_inv_depth_per_m", r.crlb_inv_depth.mean().item<double>()},
              {"mean_crlb_wavelength_nm", r.crlb_wavelength_nm.mean().item<double>()},
              {"max_condition_number", std::isfinite(r.max_condition) ? Json(r.max_condition) : Json("inf")},
              {"crlb_inv_depth_per_m", std::vector<double>(r.crlb_inv_depth.data_ptr<double>(),
                                                           r.crlb_inv_depth.data_ptr<double>() + r.crlb_inv_depth.numel())},
              {"crlb_wavelength_nm", std::vector<double>(r.crlb_wavelength_nm.data_ptr<double>(),
                                                         r.crlb_wavelength_nm.data_ptr<double>() + r.crlb_wavelength_nm.numel())}};
}

// What crlb.json's "aggregate" means for this config (its "aggregation" text).
std::string aggregation_doc(const FisherConfig& F, const std::string& nuis, bool scene_model) {
  return scene_model ?
      "per depth t = crlb_inv_depth / inv_depth_spacing, the bound of 1/z in units of one depth layer for a " +
      std::to_string(F.scene_patch_px) + "^2-px patch of a 1/f^2 Gaussian texture seen through the camera's channels "
      "with white noise " + c10::str(F.scene_noise_variance) + " of its variance (optics/scene_fisher.h); aggregate = the " +
      choice_name(F.aggregate) + (F.aggregate == CrlbAggregate::capped_mean ? " (mean of min(t, " + c10::str(F.aggregate_cap) + "))" : std::string()) +
      " of t over the depths; " + (nuis.find('N') == std::string::npos ? std::string("the texture's contrast known")
                                                                        : std::string("the texture's contrast unknown")) :
      "per (wavelength, depth) grid point t = sqrt(((crlb_inv_depth / inv_depth_spacing)^2 + (crlb_wavelength / "
      "band_width)^2) / 2), the bound in units of one depth layer and one band; aggregate = the " + choice_name(F.aggregate) +
      (F.aggregate == CrlbAggregate::capped_mean ? " (mean of min(t, " + c10::str(F.aggregate_cap) + "))" : std::string()) +
      " of t over the grid; the bound of (1/z, wavelength) with " + (nuis.empty() ? std::string("nothing else") : nuis) +
      " unknown (Schur complement)";
}

using DesignReports = std::vector<std::tuple<std::string, const optics::CrlbReport*, const optics::CrlbReport*>>;

// crlb.md and the table on stdout: each design with the nuisance parameters
// unknown (the configured bound) and known.
void write_crlb_tables(const std::string& md_path, const std::string& agg_doc, const std::string& nuis, const DesignReports& designs) {
  char line[320];
  std::string md = "# CRLB of the DOE designs\n\n" + std::string("Aggregate: ") + agg_doc + ".\n\n" +
                   "| DOE | unknown besides (1/z, λ) | aggregate | capped mean | median | mean | mean CRLB 1/z [1/m] | "
                   "mean CRLB wavelength [nm] | max condition number |\n|---|---|---|---|---|---|---|---|---|\n";
  std::string table =
      "DOE        unknown     aggregate  capped mean   median       mean   CRLB 1/z [1/m]   CRLB lambda [nm]   max condition\n";
  for (const auto& [name, r, k] : designs) {
    for (const optics::CrlbReport* x : {r, k}) {
      const std::string unk = x->nuisance.empty() ? std::string("-") : nuis;
      std::snprintf(line, sizeof line, "| %s | %s | %.4g | %.4g | %.4g | %.4g | %.4g | %.4g | %.3g |\n", name.c_str(), unk.c_str(),
                    x->aggregate.item<double>(), x->aggregate_capped, x->aggregate_median, x->aggregate_mean,
                    x->crlb_inv_depth.mean().item<double>(), x->crlb_wavelength_nm.mean().item<double>(), x->max_condition);
      md += line;
      std::snprintf(line, sizeof line, "%-10s %-10s %10.4g %12.4g %8.4g %10.4g %16.4g %18.4g %15.3g\n", name.c_str(), unk.c_str(),
                    x->aggregate.item<double>(), x->aggregate_capped, x->aggregate_median, x->aggregate_mean,
                    x->crlb_inv_depth.mean().item<double>(), x->crlb_wavelength_nm.mean().item<double>(), x->max_condition);
      table += line;
    }
  }
  write_text_file(md_path, md);
  std::printf("%s", table.c_str());
}

// The bounds a design is scored by: the configured model (point source or
// scene) with the nuisance parameters unknown and known, and the other model
// for comparison.
struct Bounds {
  Bounds(const Config& cfg, const optics::FisherGeometry& geometry, const optics::Material& mat)
      : g(geometry), material(mat), unknown(optics::fisher_settings(cfg)), known(unknown),
        scene_model(cfg.fisher.model == FisherModel::scene) {
    known.nuisance.clear();  // position and brightness known
    std::vector<double> wl_m;
    for (double w : unknown.wavelengths_nm) wl_m.push_back(w * 1e-9);
    scene.camera_response = optics::camera_response(cfg.sensor.camera, wl_m, cfg.optics.band_width_m()).to(torch::kFloat64);
    scene.noise_variance = cfg.fisher.scene_noise_variance, scene.patch_px = cfg.fisher.scene_patch_px;
  }
  optics::CrlbReport of(bool scene_bound, const torch::Tensor& h, const optics::FisherSettings& st) const {
    return scene_bound ? optics::scene_crlb_report(g, material, h, st, scene) : optics::crlb_report(g, material, h, st);
  }
  optics::CrlbReport configured(const torch::Tensor& h, const optics::FisherSettings& st) const { return of(scene_model, h, st); }

  const optics::FisherGeometry& g;
  const optics::Material& material;
  optics::FisherSettings unknown, known;
  optics::SceneFisherSettings scene;
  bool scene_model;
};

// A design and its configured bound with the nuisance parameters unknown and known.
struct Scored {
  std::string name;
  torch::Tensor height_m;  // [n, n] float64 on the design grid
  optics::CrlbReport unknown, known;
};

Scored score(const std::string& name, const torch::Tensor& h, const Bounds& b) {
  return {name, h, b.configured(h, b.unknown), b.configured(h, b.known)};
}

void log_bound(const FisherConfig& F, const optics::FisherSettings& s, bool scene_model) {
  if (scene_model)
    log::info("scene CRLB of 1/z over " + std::to_string(s.depths_m.size()) + " depths: a 1/f^2 texture through the " +
              "camera's channels (" + std::to_string(s.wavelengths_nm.size()) + " bands), noise " +
              c10::str(F.scene_noise_variance) + " of its variance, " + std::to_string(F.scene_patch_px) + "^2-px patches");
  else
    log::info("CRLB over " + std::to_string(s.wavelengths_nm.size()) + " bands x " + std::to_string(s.depths_m.size()) +
              " depths, " + c10::str(F.photons) + " photons, background " + c10::str(F.background) + " per pixel");
}

// Where the design starts on an n × n grid of the given pitch: the unwrapped
// Fresnel lens (the Fresnel DOE exactly) or flat.
torch::Tensor start_height(const FisherConfig& F, const OpticsConfig& design, const optics::Material& material, int64_t n,
                           double pitch) {
  if (F.start != FisherStart::fresnel) return torch::zeros({n, n}, torch::kFloat64);
  const double lam0 = design.doe.design_wavelength_m;
  const double z0 = design.doe.design_depth_m > 0 ? design.doe.design_depth_m : optics::middle_depth_m(design.depths_m);
  return optics::fresnel_lens_height(n, pitch, lam0, material.index(lam0), z0, design.sensor_distance_m);
}

optics::FisherDesign run_design(const FisherConfig& F, const OpticsConfig& design, const Bounds& b, double hmax) {
  log::Progress progress("fisher design", long(F.steps));
  const optics::FisherDesign d = optics::design_fisher_doe(
      b.g, [&](const torch::Tensor& h) { return b.configured(h, b.unknown); },
      start_height(F, design, b.material, design.doe_samples, design.doe_pitch_m), hmax, F, [&](int64_t k, double a) {
        progress.set_suffix(format("aggregate CRLB %.4g", a));
        if (k > 0) progress.step();
      });
  progress.finish();
  return d;
}

Json crlb_json(const FisherConfig& F, const Bounds& b, const std::string& agg_doc, const std::vector<Scored>& designs,
               const std::vector<double>& curve) {
  const auto& s = b.unknown;
  Json j{{"units", {{"crlb_inv_depth", "1/m"}, {"crlb_wavelength", "nm"}, {"aggregate", "dimensionless"}}},
         {"aggregation", agg_doc},
         {"settings", {{"photons", F.photons}, {"background_per_pixel", F.background}, {"wavelengths_nm", s.wavelengths_nm},
                       {"depths_m", s.depths_m}, {"inv_depth_spacing_per_m", s.inv_depth_spacing},
                       {"band_width_nm", s.band_width_nm}, {"window_px", F.window_px}, {"design_samples", b.g.doe_samples},
                       {"basis", choice_name(F.basis)}, {"start", choice_name(F.start)}, {"steps", F.steps}, {"aggregate", choice_name(F.aggregate)},
                       {"aggregate_cap", F.aggregate_cap}}},
         {"nuisance", Json::array()}};
  for (const auto n : s.nuisance) j["nuisance"].push_back(choice_name(n));
  for (const auto& d : designs) {
    j[d.name] = report_json(d.unknown);
    j[d.name]["without_nuisance"] = report_json(d.known);
  }
  j["fisher"]["curve"] = curve;
  j["model"] = choice_name(F.model);
  // The other bound of the same designs, so a point design and a scene design can be compared both ways.
  const bool other = !b.scene_model;
  std::string line = std::string("the ") + (other ? "scene" : "point-source") + " bound's aggregate of the same designs:";
  for (const auto& d : designs) {
    const double a = b.of(other, d.height_m, b.unknown).aggregate.item<double>();
    j[d.name][other ? "scene_aggregate" : "point_aggregate"] = a;
    line += " " + d.name + " " + c10::str(a);
  }
  log::info(line);
  return j;
}

// fisher_curve.png: the design's aggregate per step, the Fresnel and spiral DOEs' as lines.
void write_curve_plot(const std::string& path, const std::vector<double>& curve, const Scored& fresnel, const Scored& spiral) {
  std::vector<double> xs;
  for (size_t k = 0; k < curve.size(); ++k) xs.push_back(double(k));
  const double af = fresnel.unknown.aggregate.item<double>(), as = spiral.unknown.aggregate.item<double>();
  viz::write_line_plot(path, "aggregated CRLB during the Fisher design", "step",
                       {{"fisher design", xs, curve, {200, 80, 30}},
                        {"fresnel", {0.0, xs.back()}, {af, af}, {40, 40, 200}},
                        {"spiral", {0.0, xs.back()}, {as, as}, {40, 160, 40}}},
                       false);
}

int run(const AppArgs& args) {
  const Config cfg = load_config(args.config_path, args.overrides);
  const auto& F = cfg.fisher;
  const auto material = optics::Material::load(cfg.optics.material);
  const OpticsConfig design = optics::fisher_design_optics(cfg);
  const torch::Device cpu(torch::kCPU);
  const optics::FisherGeometry g =
      optics::make_fisher_geometry(optics::make_psf_spec(design, material, cpu), F.window_px, F.pixel_nodes);
  const Bounds bounds(cfg, g, material);
  setup_threads(cfg.threads);
  make_dirs(args.out_dir);
  const auto t0 = std::chrono::steady_clock::now();
  auto family = [&](DoeFamily init) {
    OpticsConfig o = design;
    o.doe.init = init;
    return optics::make_doe(o, material, cfg.seed, cpu);
  };
  const optics::Doe fresnel = family(DoeFamily::fresnel), spiral = family(DoeFamily::spiral);
  log_bound(F, bounds.unknown, bounds.scene_model);
  std::vector<Scored> designs{score("fresnel", fresnel.height().to(torch::kFloat64), bounds),
                              score("spiral", spiral.height().to(torch::kFloat64), bounds)};
  const double hmax = fresnel.max_height_m();
  const optics::FisherDesign d = run_design(F, design, bounds, hmax);
  designs.push_back(score("fisher", d.height_m, bounds));

  // Outputs: the design on the config's DOE grid.
  const auto& o = cfg.optics;
  const torch::Tensor h_full = optics::design_height_on_grid(d, start_height(F, design, material, o.doe_samples, o.doe_pitch_m),
                                                             o.doe_samples, o.doe_pitch_m, o.aperture_diameter_m, hmax);
  optics::save_height_file(args.out_dir + "/fisher_height.pt", h_full, o.doe_pitch_m);
  std::string nuis;
  for (const auto n : bounds.unknown.nuisance) nuis += (nuis.empty() ? "" : ", ") + choice_name(n);
  const std::string agg_doc = aggregation_doc(F, nuis, bounds.scene_model);
  write_text_file(args.out_dir + "/crlb.json", crlb_json(F, bounds, agg_doc, designs, d.curve).dump(2) + "\n");
  DesignReports tables;
  for (const auto& x : designs) tables.emplace_back(x.name, &x.unknown, &x.known);
  write_crlb_tables(args.out_dir + "/crlb.md", agg_doc, nuis, tables);
  write_curve_plot(args.out_dir + "/fisher_curve.png", d.curve, designs[0], designs[1]);
  {  // PSF atlas of the design with the full simulator on the config's grid.
    torch::NoGradGuard ng;
    const optics::PsfSimulator sim(optics::make_psf_spec(o, material, cpu));
    viz::write_psf_atlas(args.out_dir + "/psf_atlas_fisher.png", sim.compute(h_full.to(torch::kFloat32)).psf,
                         sim.spec().wavelengths_m, sim.spec().depths_m);
  }
  write_resolved_config(cfg, args.out_dir);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  log::info("wrote crlb.json, crlb.md, fisher_height.pt, fisher_curve.png, psf_atlas_fisher.png to " + args.out_dir +
            " (" + c10::str(secs) + " s)");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  AppSpec spec{"hsd_fisher", kUsage, {}, {}, true, true};
  return run_app(spec, argc, argv, run);
}
