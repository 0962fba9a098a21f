#include "data/ray_cast.h"

#include <cmath>
#include <limits>

#include <torch/torch.h>

namespace hsd::data::raycast {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
}  // namespace

// Per-pixel ray directions d = (dx, dy, 1): a hit at parameter t lies at t·d, depth Z = t.
Rays make_rays(int64_t H, int64_t W, double fov_deg) {
  Rays r;
  const double f = 0.5 * double(W) / std::tan(0.5 * fov_deg * M_PI / 180.0);
  r.tan_h = 0.5 * double(W) / f, r.tan_v = 0.5 * double(H) / f;
  r.focal_px = f;
  const torch::Tensor xs = (torch::arange(W, f64) + 0.5 - 0.5 * double(W)) / f;
  const torch::Tensor ys = (torch::arange(H, f64) + 0.5 - 0.5 * double(H)) / f;
  r.dx = xs.view({1, W}).expand({H, W});
  r.dy = ys.view({H, 1}).expand({H, W});
  return r;
}

torch::Tensor inf_like(const torch::Tensor& x) { return torch::full_like(x, kInf); }

// Plane n·P = c.
Hit hit_plane(const Rays& r, std::array<double, 3> n, double c) {
  const torch::Tensor nd = n[0] * r.dx + n[1] * r.dy + n[2];
  torch::Tensor t = c / nd;
  t = torch::where((nd.abs() > 1e-12) & (t > 0), t, inf_like(t));
  return {t, torch::full_like(t, n[0]), torch::full_like(t, n[1]), torch::full_like(t, n[2])};
}

// Rectangle: centre C, unit axes u, v (normal n = u × v), half sizes a, b.
Hit hit_card(const Rays& r, std::array<double, 3> C, std::array<double, 3> u, std::array<double, 3> v, double a, double b) {
  const std::array<double, 3> n{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  Hit h = hit_plane(r, n, n[0] * C[0] + n[1] * C[1] + n[2] * C[2]);
  const torch::Tensor px = h.t * r.dx - C[0], py = h.t * r.dy - C[1], pz = h.t - C[2];
  const torch::Tensor su = px * u[0] + py * u[1] + pz * u[2], sv = px * v[0] + py * v[1] + pz * v[2];
  h.t = torch::where((su.abs() <= a) & (sv.abs() <= b), h.t, inf_like(h.t));
  return h;
}

Hit hit_sphere(const Rays& r, std::array<double, 3> C, double rad) {
  const torch::Tensor A = r.dx * r.dx + r.dy * r.dy + 1.0;
  const torch::Tensor B = -2.0 * (r.dx * C[0] + r.dy * C[1] + C[2]);
  const double Cc = C[0] * C[0] + C[1] * C[1] + C[2] * C[2] - rad * rad;
  const torch::Tensor disc = B * B - 4.0 * A * Cc;
  torch::Tensor t = (-B - disc.clamp_min(0).sqrt()) / (2.0 * A);
  t = torch::where((disc >= 0) & (t > 0), t, inf_like(t));
  const torch::Tensor tt = torch::where(torch::isfinite(t), t, torch::zeros_like(t));
  return {t, (tt * r.dx - C[0]) / rad, (tt * r.dy - C[1]) / rad, (tt - C[2]) / rad};
}

// Vertical cylinder: axis through (cx, ·, cz), radius rad, y in [y_top, y_bottom] (y down), capped at both ends.
Hit hit_cylinder(const Rays& r, double cx, double cz, double rad, double y_top, double y_bottom) {
  const torch::Tensor A = r.dx * r.dx + 1.0;
  const torch::Tensor B = -2.0 * (r.dx * cx + cz);
  const double Cc = cx * cx + cz * cz - rad * rad;
  const torch::Tensor disc = B * B - 4.0 * A * Cc;
  torch::Tensor t = (-B - disc.clamp_min(0).sqrt()) / (2.0 * A);
  const torch::Tensor y = t * r.dy;
  t = torch::where((disc >= 0) & (t > 0) & (y >= y_top) & (y <= y_bottom), t, inf_like(t));
  const torch::Tensor tt = torch::where(torch::isfinite(t), t, torch::zeros_like(t));
  Hit side{t, (tt * r.dx - cx) / rad, torch::zeros_like(t), (tt - cz) / rad};
  // Top cap: plane y = y_top (seen from above when y_top > 0, i.e. below the eye).
  torch::Tensor tc = y_top / r.dy;
  const torch::Tensor qx = tc * r.dx - cx, qz = tc - cz;
  tc = torch::where((r.dy.abs() > 1e-12) & (tc > 0) & (qx * qx + qz * qz <= rad * rad), tc, inf_like(tc));
  // Bottom cap: plane y = y_bottom (seen from below when the cylinder floats above the eye).
  torch::Tensor tb = y_bottom / r.dy;
  const torch::Tensor bx = tb * r.dx - cx, bz = tb - cz;
  tb = torch::where((r.dy.abs() > 1e-12) & (tb > 0) & (bx * bx + bz * bz <= rad * rad), tb, inf_like(tb));
  const torch::Tensor top = (tc < side.t) & (tc <= tb), bottom = (tb < side.t) & (tb < tc);
  const torch::Tensor zero = torch::zeros_like(t), one = torch::ones_like(t);
  return {torch::where(top, tc, torch::where(bottom, tb, side.t)),
          torch::where(top | bottom, zero, side.nx),
          torch::where(top, -one, torch::where(bottom, one, side.ny)),
          torch::where(top | bottom, zero, side.nz)};
}

// Box: centre C, half extents e, rotated by theta about the vertical (slab method in the box frame).
Hit hit_box(const Rays& r, std::array<double, 3> C, std::array<double, 3> e, double theta) {
  const double c = std::cos(theta), s = std::sin(theta);
  // Box frame: x' = c x + s z, z' = −s x + c z (rotation about y), origin at C.
  const double ox = -(c * C[0] + s * C[2]), oy = -C[1], oz = -(-s * C[0] + c * C[2]);
  const torch::Tensor dx = c * r.dx + s, dy = r.dy, dz = -s * r.dx + c;
  const std::array<torch::Tensor, 3> d{dx, dy, dz};
  const std::array<double, 3> o{ox, oy, oz};
  torch::Tensor tmin = torch::full_like(dx, -kInf), tmax = torch::full_like(dx, kInf);
  torch::Tensor axis = torch::zeros_like(dx), sign = torch::zeros_like(dx);
  for (int i = 0; i < 3; ++i) {
    const torch::Tensor inv = 1.0 / torch::where(d[size_t(i)].abs() < 1e-12, torch::full_like(dx, 1e-12), d[size_t(i)]);
    const torch::Tensor t1 = (-e[size_t(i)] - o[size_t(i)]) * inv, t2 = (e[size_t(i)] - o[size_t(i)]) * inv;
    const torch::Tensor lo = torch::minimum(t1, t2), hi = torch::maximum(t1, t2);
    const torch::Tensor better = lo > tmin;
    axis = torch::where(better, torch::full_like(dx, double(i)), axis);
    sign = torch::where(better, torch::where(t1 < t2, -torch::ones_like(dx), torch::ones_like(dx)), sign);
    tmin = torch::maximum(tmin, lo);
    tmax = torch::minimum(tmax, hi);
  }
  const torch::Tensor t = torch::where((tmax >= tmin) & (tmin > 0), tmin, inf_like(tmin));
  // Normal in the box frame, back to the world (inverse rotation).
  const torch::Tensor nxp = torch::where(axis == 0, sign, torch::zeros_like(dx));
  const torch::Tensor nyp = torch::where(axis == 1, sign, torch::zeros_like(dx));
  const torch::Tensor nzp = torch::where(axis == 2, sign, torch::zeros_like(dx));
  return {t, c * nxp - s * nzp, nyp, s * nxp + c * nzp};
}

Composite zbuffer(const std::vector<Surface>& s, int64_t H, int64_t W) {
  Composite c{torch::full({H, W}, kInf, f64), torch::full({H, W}, -1, torch::kLong), torch::zeros({H, W}, f64),
              torch::zeros({H, W}, f64), torch::zeros({H, W}, f64)};
  for (size_t k = 0; k < s.size(); ++k) {
    const torch::Tensor nearer = s[k].hit.t < c.t;
    c.t = torch::where(nearer, s[k].hit.t, c.t);
    c.id = torch::where(nearer, torch::full_like(c.id, int64_t(k)), c.id);
    c.nx = torch::where(nearer, s[k].hit.nx, c.nx);
    c.ny = torch::where(nearer, s[k].hit.ny, c.ny);
    c.nz = torch::where(nearer, s[k].hit.nz, c.nz);
  }
  return c;
}

Hit hit_tilted_wall(const Rays& r, double a, double b, double* wall_z, double max_depth_m) {
  const std::array<double, 3> n{std::sin(a) * std::cos(b), std::sin(b), std::cos(a) * std::cos(b)};
  Hit h = hit_plane(r, n, n[2] * *wall_z);
  const double far = torch::where(torch::isfinite(h.t), h.t, torch::zeros_like(h.t)).max().item<double>();
  if (far > max_depth_m) {
    *wall_z *= max_depth_m / far;
    h = hit_plane(r, n, n[2] * *wall_z);
  }
  return h;
}

std::pair<torch::Tensor, torch::Tensor> surface_coordinates(const Composite& c, const Rays& r, const torch::Tensor& depth) {
  const torch::Tensor px = depth * r.dx, py = depth * r.dy, pz = depth;
  const torch::Tensor ax = c.nx.abs(), ay = c.ny.abs(), az = c.nz.abs();
  const torch::Tensor major_x = (ax >= ay) & (ax >= az), major_y = (ay > ax) & (ay >= az);
  return {torch::where(major_x, pz, px), torch::where(major_y, pz, py)};
}

torch::Tensor lambert_cosine(const Composite& c, const Rays& r) {
  const double ll = std::sqrt(0.4 * 0.4 + 0.6 * 0.6 + 0.7 * 0.7);
  const std::array<double, 3> l{-0.4 / ll, -0.6 / ll, -0.7 / ll};
  torch::Tensor ndotl = c.nx * l[0] + c.ny * l[1] + c.nz * l[2];
  const torch::Tensor facing = (c.nx * r.dx + c.ny * r.dy + c.nz) < 0;  // normal towards the camera
  ndotl = torch::where(facing, ndotl, -ndotl);
  return ndotl.clamp_min(0);
}

}  // namespace hsd::data::raycast
