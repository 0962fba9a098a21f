// Ray casting of simple surfaces for the scene generators: a pinhole camera
// at the origin looking along +z (x right, y down, so rows grow downward as in
// the image), one ray per pixel centre, d = (dx, dy, 1): a hit at parameter t
// lies at t·d and its depth is Z = t. Planes, rectangles (cards), spheres,
// capped vertical cylinders and boxes rotated about the vertical; a z-buffer
// keeps the nearest hit per ray (true occlusions). All tensors float64 [H, W].
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <torch/types.h>

namespace hsd::data::raycast {

struct Rays {
  torch::Tensor dx, dy;  // [H, W]
  double tan_h = 0, tan_v = 0;  // tangents of the half fields of view
  double focal_px = 0;          // focal length in pixels
};
// fov_deg: horizontal field of view.
Rays make_rays(int64_t H, int64_t W, double fov_deg);

struct Hit {
  torch::Tensor t;           // [H, W], +inf where missed
  torch::Tensor nx, ny, nz;  // unit normal (any orientation)
};
torch::Tensor inf_like(const torch::Tensor& x);
// Plane n·P = c.
Hit hit_plane(const Rays& r, std::array<double, 3> n, double c);
// Rectangle: centre C, unit axes u, v (normal u × v), half sizes a, b.
Hit hit_card(const Rays& r, std::array<double, 3> C, std::array<double, 3> u, std::array<double, 3> v, double a, double b);
Hit hit_sphere(const Rays& r, std::array<double, 3> C, double rad);
// Vertical cylinder: axis through (cx, ·, cz), radius rad, y in [y_top, y_bottom] (y down), capped at both ends.
Hit hit_cylinder(const Rays& r, double cx, double cz, double rad, double y_top, double y_bottom);
// Box: centre C, half extents e, rotated by theta about the vertical.
Hit hit_box(const Rays& r, std::array<double, 3> C, std::array<double, 3> e, double theta);
// A back wall tilted by yaw a and pitch b [rad] crossing the axis at *wall_z,
// pulled in (and *wall_z with it) so that no visible point lies beyond max_depth_m.
Hit hit_tilted_wall(const Rays& r, double a, double b, double* wall_z, double max_depth_m);

struct Surface {
  std::string what;
  Hit hit;
};
struct Composite {
  torch::Tensor t, id, nx, ny, nz;  // nearest hit, its surface index (-1 = none), its normal
};
Composite zbuffer(const std::vector<Surface>& s, int64_t H, int64_t W);

// In-surface coordinates [m] of the hits at `depth`: the two world axes least
// aligned with each pixel's normal ({u, v}, [H, W] each).
std::pair<torch::Tensor, torch::Tensor> surface_coordinates(const Composite& c, const Rays& r, const torch::Tensor& depth);
// Lambert's cosine max(0, n·l) for one light up-left-front of the scene, the
// normal turned towards the camera [H, W].
torch::Tensor lambert_cosine(const Composite& c, const Rays& r);

}  // namespace hsd::data::raycast
