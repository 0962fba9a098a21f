#include "optics/fabrication_tolerance.h"

#include <stdexcept>

namespace hsd::optics {

std::vector<ToleranceSweep> tolerance_sweeps(const FabricationToleranceConfig& t) {
  return {{"etch_depth", "etch-depth error [%]", 100.0, t.height_scale_error},
          {"roughness_white", "white roughness RMS [nm]", 1e9, t.roughness_rms_m},
          {"roughness_correlated", "correlated roughness RMS [nm]", 1e9, t.roughness_rms_m},
          {"misalignment", "mask misalignment [um]", 1e6, t.misalignment_m},
          {"edge_rounding", "edge blur sigma [um]", 1e6, t.edge_blur_m},
          {"decentre", "DOE decentre [um]", 1e6, t.decentre_m}};
}

FabricationErrorConfig tolerance_error(const ToleranceSweep& sweep, double size, const FabricationToleranceConfig& t) {
  FabricationErrorConfig e;
  if (sweep.kind == "etch_depth") e.height_scale_error = size;
  else if (sweep.kind == "roughness_white") e.roughness_rms_m = size;
  else if (sweep.kind == "roughness_correlated") e.roughness_rms_m = size, e.roughness_correlation_m = t.roughness_correlation_m;
  else if (sweep.kind == "misalignment") e.misalignment_m = size;
  else if (sweep.kind == "edge_rounding") e.edge_blur_m = size;
  else if (sweep.kind == "decentre") e.decentre_m = size;
  else throw std::invalid_argument("unknown tolerance sweep " + sweep.kind);
  return e;
}

}  // namespace hsd::optics
