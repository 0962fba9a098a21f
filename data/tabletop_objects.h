// Objects on (or above) a table for the tabletop scene layouts (classic and
// textured): spheres, boxes rotated about the vertical, capped vertical
// cylinders and slanted rectangular cards, placed uniformly in inverse depth
// over [depth_min, far], each sized relative to the half field of view at its
// distance, standing on the table plane y = y_table (y down) or floating.
// Random draws come in a fixed order (scenes are reproducible across builds).
#pragma once
#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "data/ray_cast.h"

namespace hsd::data {

struct ObjectPlacement {
  double size_min = 0.08, size_max = 0.25;  // object size as a fraction of the half-width at its distance
  double on_table_prob = 0.6;               // chance an object stands on the table (when there is one)
};

// Appends n objects to `surfaces` (and counts them by kind in `counts`).
void add_tabletop_objects(const raycast::Rays& r, int64_t n, double depth_min_m, double far_m, bool table, double y_table,
                          const ObjectPlacement& p, std::mt19937_64& rng, std::vector<raycast::Surface>& surfaces,
                          std::map<std::string, int>& counts);

}  // namespace hsd::data
