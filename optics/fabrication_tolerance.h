// The tolerance sweep of hsd_fabricate --tolerance: each error a fab makes
// (optics/fabrication_error.h), one kind at a time, at the sizes
// fabrication.tolerance lists; the fabricated design without error (the
// K-level map on the refined grid) is every sweep's reference.
#pragma once
#include <string>
#include <vector>

#include "common/config.h"

namespace hsd::optics {

enum class FabricationErrorKind { etch_depth, roughness_white, roughness_correlated, misalignment, edge_rounding, decentre };

struct ToleranceSweep {
  FabricationErrorKind kind;
  std::string name;           // the kind as written to tolerance.json: etch_depth, roughness_white, ...
  std::string size_label;     // what a size is, with its unit, for tables and plots
  double unit_scale = 1.0;    // size × unit_scale = the number shown (e.g. 1e9 for nm)
  std::vector<double> sizes;  // SI (relative for etch_depth)
};

// The six sweeps of a config, in a fixed order.
std::vector<ToleranceSweep> tolerance_sweeps(const FabricationToleranceConfig& t);

// The error of one sweep at one size (all other errors 0).
FabricationErrorConfig tolerance_error(const ToleranceSweep& sweep, double size, const FabricationToleranceConfig& t);

}  // namespace hsd::optics
