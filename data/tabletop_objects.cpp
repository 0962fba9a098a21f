#include "data/tabletop_objects.h"

#include <array>
#include <cmath>

#include <torch/torch.h>

namespace hsd::data {

using namespace raycast;

void add_tabletop_objects(const Rays& r, int64_t n, double dmin, double far_obj, bool table, double y_t,
                          const ObjectPlacement& p, std::mt19937_64& rng, std::vector<Surface>& surfaces,
                          std::map<std::string, int>& counts) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  auto uni = [&](double a, double b) { return a + (b - a) * U(rng); };
  for (int64_t k = 0; k < n; ++k) {
    const double inv = uni(1.0 / far_obj, 1.0 / dmin);
    double zc = 1.0 / inv;
    const double s = uni(p.size_min, p.size_max) * zc * r.tan_h;  // size relative to the half-width at that distance
    zc = std::max(zc, dmin + 1.8 * s);                             // nearest surface stays beyond dmin
    const double xc = uni(-0.9, 0.9) * zc * r.tan_h;
    const bool on_table = table && U(rng) < p.on_table_prob && zc * r.tan_v > y_t * 0.5;
    const int kind = std::uniform_int_distribution<int>(0, 3)(rng);
    if (kind == 0) {
      const double yc = on_table ? y_t - s : uni(-0.8, 0.8) * zc * r.tan_v;
      surfaces.push_back({"sphere", hit_sphere(r, {xc, yc, zc}, s)});
    } else if (kind == 1) {
      const std::array<double, 3> e{s * uni(0.5, 1.2), s * uni(0.5, 1.2), s * uni(0.5, 1.0)};
      const double yc = on_table ? y_t - e[1] : uni(-0.8, 0.8) * zc * r.tan_v;
      surfaces.push_back({"box", hit_box(r, {xc, yc, zc}, e, uni(0, M_PI / 2))});
    } else if (kind == 2) {
      const double h = s * uni(1.0, 3.0);
      const double bottom = on_table ? y_t : uni(-0.5, 0.8) * zc * r.tan_v;
      surfaces.push_back({"cylinder", hit_cylinder(r, xc, zc, s * uni(0.4, 0.8), bottom - h, bottom)});
    } else {
      const double yaw = uni(-50, 50) * M_PI / 180, pitch = uni(-30, 30) * M_PI / 180;
      const std::array<double, 3> u{std::cos(yaw), 0, std::sin(yaw)};
      const std::array<double, 3> v{-std::sin(yaw) * std::sin(pitch), std::cos(pitch), std::cos(yaw) * std::sin(pitch)};
      const double a = s * uni(0.8, 1.5), b = s * uni(0.8, 1.5);
      const double yc = on_table ? y_t - b * std::cos(pitch) : uni(-0.8, 0.8) * zc * r.tan_v;
      surfaces.push_back({"card", hit_card(r, {xc, yc, zc}, u, v, a, b)});
    }
    counts[surfaces.back().what]++;
  }
}

}  // namespace hsd::data
