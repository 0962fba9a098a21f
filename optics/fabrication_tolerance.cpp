#include "optics/fabrication_tolerance.h"

namespace hsd::optics {

std::vector<ToleranceSweep> tolerance_sweeps(const FabricationToleranceConfig& t) {
  using K = FabricationErrorKind;
  return {{K::etch_depth, "etch_depth", "etch-depth error [%]", 100.0, t.height_scale_error},
          {K::roughness_white, "roughness_white", "white roughness RMS [nm]", 1e9, t.roughness_rms_m},
          {K::roughness_correlated, "roughness_correlated", "correlated roughness RMS [nm]", 1e9, t.roughness_rms_m},
          {K::misalignment, "misalignment", "mask misalignment [um]", 1e6, t.misalignment_m},
          {K::edge_rounding, "edge_rounding", "edge blur sigma [um]", 1e6, t.edge_blur_m},
          {K::decentre, "decentre", "DOE decentre [um]", 1e6, t.decentre_m}};
}

FabricationErrorConfig tolerance_error(const ToleranceSweep& sweep, double size, const FabricationToleranceConfig& t) {
  FabricationErrorConfig e;
  switch (sweep.kind) {
    case FabricationErrorKind::etch_depth: e.height_scale_error = size; break;
    case FabricationErrorKind::roughness_white: e.roughness_rms_m = size; break;
    case FabricationErrorKind::roughness_correlated:
      e.roughness_rms_m = size, e.roughness_correlation_m = t.roughness_correlation_m;
      break;
    case FabricationErrorKind::misalignment: e.misalignment_m = size; break;
    case FabricationErrorKind::edge_rounding: e.edge_blur_m = size; break;
    case FabricationErrorKind::decentre: e.decentre_m = size; break;
  }
  return e;
}

}  // namespace hsd::optics
