#include "model/net_options.h"

#include <algorithm>

namespace hsd::model {

NetOptions net_options(const Config& cfg) {
  NetOptions o;
  o.bands = int64_t(cfg.optics.wavelengths_nm.size());
  o.base_width = cfg.model.base_width;
  o.levels = cfg.model.levels;
  o.norm = cfg.model.norm;
  const auto& d = cfg.optics.depths_m;
  const double near = std::min(*std::min_element(d.begin(), d.end()), cfg.data.generator.depth_min_m);
  const double far = std::max(*std::max_element(d.begin(), d.end()), cfg.data.generator.depth_max_m);
  // model.depth_margin widens the sigmoid's range in inverse depth at both ends
  // (the far end kept at >= half its inverse depth, so it stays finite).
  const double span = 1.0 / near - 1.0 / far, m = cfg.model.depth_margin * span;
  o.depth_min_m = 1.0 / (1.0 / near + m);
  o.depth_max_m = 1.0 / std::max(1.0 / far - m, 0.5 / far);
  o.preinverse_layers = cfg.model.preinverse == Preinverse::wiener ? int64_t(d.size()) : 0;
  o.fuse_defocus_reader = cfg.model.fuse_defocus_reader;
  o.fusion = {cfg.model.fusion_reader_box_px, cfg.model.fusion_cost_radius_px, cfg.model.fusion_depth_radius_px,
              cfg.model.fusion_guide_eps};
  o.read_illuminant = cfg.model.read_illuminant;
  o.illuminant_reader = {cfg.model.illuminant_block_px, cfg.model.illuminant_effective_blocks};
  o.edge_prior = {cfg.model.edge_prior_weight, cfg.model.edge_prior_iterations, cfg.model.edge_prior_rho_start,
                  cfg.model.edge_prior_rho_factor};
  o.layer_depths_m = d;
  o.preinverse_reg = cfg.model.preinverse_reg;
  o.residual_preinverse = cfg.model.residual == ResidualBase::preinverse;
  o.residual_spectral_wiener = cfg.model.residual == ResidualBase::spectral_wiener;
  o.learned_spectral_map = cfg.model.spectral_map == SpectralMap::learned;
  o.base_as_input = cfg.model.base_as_input;
  o.project_residual = cfg.model.project_residual;
  o.refine_width = cfg.model.refine_width;
  o.defocus_cost = cfg.model.defocus_cost;
  o.defocus_cost_gradient = cfg.model.defocus_cost_gradient;
  o.depth_bins = cfg.model.depth_bins;
  return o;
}

}  // namespace hsd::model
