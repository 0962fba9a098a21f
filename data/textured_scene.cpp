#include "data/textured_scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <random>

#include <torch/torch.h>

#include "common/error.h"
#include "data/ray_cast.h"
#include "data/tabletop_objects.h"

namespace hsd::data {

namespace {

using namespace raycast;
const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
constexpr int64_t kSpectraPerSurface = 4;  // per material
constexpr int64_t kMaterials = 3;          // per surface

// What a surface looks like: its photo and where the photo sits on it, its
// measured spectra, its contrast and the gain of the independent noise weight.
struct SurfaceLook {
  int64_t texture = 0;
  torch::Tensor spectra;  // [kMaterials·K, L]: material 0's K spectra, then material 1's, ...
  double split_lo = 0.35, split_hi = 0.65;  // material = (m > split_lo) + (m > split_hi), m the second noise field
  double contrast = 1.0, noise_gain = 1.0;
  double sharpness = 1.0;  // γ of the weights: ŵ ∝ w^γ (large: near-pure measured spectra in patches)
};

// Per-pixel surface map filled by a layout.
struct SurfaceMap {
  torch::Tensor id;      // long [H, W], -1 = no surface (invalid)
  torch::Tensor tx, ty;  // texture-pixel coordinates [H, W]
  torch::Tensor shade;   // [H, W] in (0, 1]
};

double log_uniform(std::mt19937_64& rng, double a, double b) {
  return std::exp(std::uniform_real_distribution<double>(std::log(a), std::log(b))(rng));
}

SurfaceLook draw_look(const SceneSources& src, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  SurfaceLook s;
  s.texture = std::uniform_int_distribution<int64_t>(0, src.textures.size() - 1)(rng);
  s.spectra = src.spectra.draw(rng, kMaterials * kSpectraPerSurface);
  s.split_lo = 0.25 + 0.2 * U(rng);
  s.split_hi = 0.55 + 0.2 * U(rng);
  s.contrast = 0.5 + 0.5 * U(rng);
  s.noise_gain = 0.3 + 1.2 * U(rng);
  s.sharpness = 4.0 + 8.0 * U(rng);
  return s;
}

// A periodic 1/f^beta field [H, W] (amplitude spectrum), scaled to [0, 1].
torch::Tensor fractal_field(int64_t H, int64_t W, double beta, std::mt19937_64& rng) {
  const torch::Tensor ky = torch::fft::fftfreq(H, 1.0, f64).view({H, 1}), kx = torch::fft::fftfreq(W, 1.0, f64).view({1, W});
  const torch::Tensor k = (ky * ky + kx * kx).sqrt().clamp_min(1.0 / double(std::max(H, W)));
  std::vector<double> ph(size_t(H * W));
  std::uniform_real_distribution<double> U(0.0, 2.0 * M_PI);
  for (auto& p : ph) p = U(rng);
  torch::Tensor x = torch::real(torch::fft::ifft2(torch::polar(k.pow(-beta), torch::tensor(ph, f64).view({H, W}))));
  return (x - x.min()) / (x.max() - x.min()).clamp_min(1e-12);
}

// Texture-pixel coordinates of surface coordinates (a, b) (any unit), with
// `units_per_texel` units per texture pixel, rotated by theta and offset.
std::pair<torch::Tensor, torch::Tensor> texel_coords(const torch::Tensor& a, const torch::Tensor& b, double units_per_texel,
                                                     double theta, double ox, double oy) {
  const double c = std::cos(theta) / units_per_texel, s = std::sin(theta) / units_per_texel;
  return {c * a - s * b + ox, s * a + c * b + oy};
}

// The texture pixels each scene pixel spans [H, W]: the longer of the texture
// coordinates' steps to the next pixel in x and in y. Each step is the shorter
// of the differences to the two neighbours on the same surface (one where the
// other is on another surface; 0 without either), so a seam inside a surface,
// where the projection switches axes and the coordinates jump, counts for no pixel.
torch::Tensor texel_footprint(const SurfaceMap& m) {
  const double inf = std::numeric_limits<double>::infinity();
  auto step = [&](int dim) {
    const int64_t n = m.id.size(dim);
    if (n < 2) return torch::zeros_like(m.tx);
    const torch::Tensor a = m.id.narrow(dim, 0, n - 1), b = m.id.narrow(dim, 1, n - 1);
    const torch::Tensor dx = m.tx.narrow(dim, 1, n - 1) - m.tx.narrow(dim, 0, n - 1);
    const torch::Tensor dy = m.ty.narrow(dim, 1, n - 1) - m.ty.narrow(dim, 0, n - 1);
    // d2[i]: squared step between pixels i and i + 1 along dim, +inf across surfaces.
    const torch::Tensor d2 = torch::where((a == b) & (a >= 0), dx * dx + dy * dy, torch::full_like(dx, inf));
    const torch::Tensor pad = torch::full_like(m.tx.narrow(dim, 0, 1), inf);
    const torch::Tensor fwd = torch::cat({d2, pad}, dim), bwd = torch::cat({pad, d2}, dim);
    const torch::Tensor g2 = torch::minimum(fwd, bwd);
    return torch::where(torch::isfinite(g2), g2, torch::zeros_like(g2));
  };
  return torch::maximum(step(1), step(0)).sqrt();
}

// The reflectance cube [L, H, W] float64 from the surface map (formula in the
// header); area_filter: each pixel averages the photo over its footprint
// (TextureBank::sample_area), else the photo is point sampled.
torch::Tensor paint(const SurfaceMap& m, const std::vector<SurfaceLook>& looks, const TextureBank& tex,
                    const torch::Tensor& noise, const torch::Tensor& materials, int64_t L, bool area_filter) {
  const int64_t H = m.id.size(0), W = m.id.size(1), n = int64_t(looks.size());
  const torch::Tensor id = m.id.reshape(-1);
  const torch::Tensor valid = id >= 0;
  const torch::Tensor idc = id.clamp_min(0);
  const size_t ns = size_t(n);
  std::vector<int64_t> tex_of(ns);
  std::vector<double> contrast(ns), gain(ns), sharp(ns), lo(ns), hi(ns);
  for (int64_t k = 0; k < n; ++k)
    tex_of[size_t(k)] = looks[size_t(k)].texture, contrast[size_t(k)] = looks[size_t(k)].contrast,
    gain[size_t(k)] = looks[size_t(k)].noise_gain, sharp[size_t(k)] = looks[size_t(k)].sharpness,
    lo[size_t(k)] = looks[size_t(k)].split_lo, hi[size_t(k)] = looks[size_t(k)].split_hi;
  const torch::Tensor pix_tex = torch::tensor(tex_of, torch::kLong).index_select(0, idc);
  // The photos' linear RGB and normalised luminance, one photo at a time over its pixels.
  torch::Tensor rgb = torch::zeros({3, H * W}, f64), ynorm = torch::zeros({H * W}, f64);
  const torch::Tensor tx = m.tx.reshape(-1), ty = m.ty.reshape(-1);
  const torch::Tensor foot = area_filter ? texel_footprint(m).reshape(-1) : torch::Tensor();
  for (int64_t t = 0; t < tex.size(); ++t) {
    const torch::Tensor idx = (valid & (pix_tex == t)).nonzero().squeeze(1);
    if (idx.numel() == 0) continue;
    const torch::Tensor x = tx.index_select(0, idx).view({1, -1}), y = ty.index_select(0, idx).view({1, -1});
    const torch::Tensor f = area_filter ? foot.index_select(0, idx).view({1, -1}) : torch::Tensor();
    auto sample = [&](const torch::Tensor& xs, const torch::Tensor& ys) {
      return area_filter ? tex.sample_area(t, xs, ys, f) : tex.sample(t, xs, ys);
    };
    const torch::Tensor c = sample(x, y).view({3, -1});
    if (tex.is_grey(t)) {  // three independent weights: the photo at two more places for the second and third
      const torch::Tensor c2 = sample(x + 173.3, y + 91.7).view({3, -1});
      const torch::Tensor c3 = sample(y - 121.1, x + 237.9).view({3, -1});
      rgb.index_copy_(1, idx, torch::stack({c[0], c2[0], c3[0]}));
    } else {
      rgb.index_copy_(1, idx, c);
    }
    const torch::Tensor lum = (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]) / tex.luminance_p95(t);
    ynorm.index_copy_(0, idx, lum.clamp(0.0, 1.0));
  }
  const torch::Tensor pc = torch::tensor(contrast, f64).index_select(0, idc);
  const torch::Tensor pg = torch::tensor(gain, f64).index_select(0, idc);
  const torch::Tensor ps = torch::tensor(sharp, f64).index_select(0, idc);
  torch::Tensor w = torch::cat({rgb, (pg * noise.reshape(-1)).unsqueeze(0)}, 0) + 1e-3;  // [4, HW]
  w = w / std::get<0>(w.max(0, true));  // in (0, 1], so w^γ cannot overflow
  w = w.pow(ps.unsqueeze(0));
  w = w / w.sum(0, true);
  std::vector<torch::Tensor> spectra;
  for (const auto& l : looks) spectra.push_back(l.spectra);
  const torch::Tensor S = torch::stack(spectra);  // [n, kMaterials·K, L]
  const torch::Tensor mf = materials.reshape(-1);
  const torch::Tensor material = (mf > torch::tensor(lo, f64).index_select(0, idc)).to(torch::kLong) +
                                 (mf > torch::tensor(hi, f64).index_select(0, idc)).to(torch::kLong);
  torch::Tensor mix = torch::zeros({H * W, L}, f64);
  const torch::Tensor flat = S.reshape({-1, L});  // row (surface, slot)
  for (int64_t k = 0; k < kSpectraPerSurface; ++k) {
    const torch::Tensor row = idc * (kMaterials * kSpectraPerSurface) + material * kSpectraPerSurface + k;
    mix += w[k].unsqueeze(1) * flat.index_select(0, row);
  }
  const torch::Tensor bright = (1.0 - pc) + pc * ynorm;
  torch::Tensor refl = mix * (bright * m.shade.reshape(-1)).unsqueeze(1);
  refl = torch::where(valid.unsqueeze(1), refl, torch::full_like(refl, 0.05));  // invalid background: dim neutral
  return refl.t().reshape({L, H, W}).clamp(0.0, 1.0);
}

GeneratedScene finish(const torch::Tensor& refl, const torch::Tensor& depth, const torch::Tensor& valid,
                      const std::vector<double>& wavelengths_m, const std::string& what) {
  GeneratedScene out;
  out.scene.wavelengths_m = wavelengths_m;
  out.scene.kind = SpectralKind::Reflectance;
  out.scene.spectral = refl.to(torch::kFloat32);
  out.scene.depth_m = depth.to(torch::kFloat32).unsqueeze(0);
  out.scene.mask = valid.to(torch::kFloat32).unsqueeze(0);
  const torch::Tensor dv = depth.masked_select(valid);
  char buf[320];
  std::snprintf(buf, sizeof buf, "%s; depth %.2f-%.2f m; %.1f %% invalid", what.c_str(),
                dv.numel() ? dv.min().item<double>() : 0.0, dv.numel() ? dv.max().item<double>() : 0.0,
                100.0 * (1.0 - valid.to(torch::kFloat64).mean().item<double>()));
  out.notes = buf;
  return out;
}

}  // namespace

SceneLayout pick_layout(const GeneratorConfig& g, uint64_t seed) {
  std::mt19937_64 rng(seed ^ 0xA0761D6478BD642Full);
  double total = 0;
  for (const auto& [name, w] : g.layouts) total += w;
  const double u = std::uniform_real_distribution<double>(0.0, total)(rng);
  double acc = 0;
  for (const auto& [name, w] : g.layouts) {
    acc += w;
    if (w > 0 && u < acc) return name;
  }
  for (auto it = g.layouts.rbegin(); it != g.layouts.rend(); ++it)
    if (it->second > 0) return it->first;
  throw InputError("config key data.generator.layouts: no layout has a positive weight");
}

GeneratedScene generate_textured_tabletop_scene(const GeneratorConfig& g, const SceneSources& src,
                                                const std::vector<double>& wavelengths_m, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  auto uni = [&](double a, double b) { return a + (b - a) * U(rng); };
  const int64_t H = g.height_px, W = g.width_px, L = int64_t(wavelengths_m.size());
  const Rays r = make_rays(H, W, g.fov_deg);
  const double dmin = g.depth_min_m, dmax = g.depth_max_m;
  std::vector<Surface> surfaces;
  std::map<std::string, int> counts;

  // Back wall, tilted, at 0.35-1.0 of depth_max_m (uniform in inverse depth), nothing beyond dmax.
  const double a = uni(-25, 25) * M_PI / 180, b = uni(-15, 15) * M_PI / 180;
  double wall_z = std::max(1.0 / uni(1.0 / dmax, 1.0 / (0.35 * dmax)), 1.3 * dmin);
  surfaces.push_back({"wall", hit_tilted_wall(r, a, b, &wall_z, dmax)});
  // Table below the eye in 80 % of scenes, its nearest visible point >= dmin.
  const bool table = U(rng) < 0.8;
  const double y_t = uni(1.0, 1.6) * dmin * r.tan_v;
  if (table) {
    Hit h = hit_plane(r, {0, 1, 0}, y_t);
    h.t = torch::where(h.t <= std::min(wall_z * 1.001, dmax), h.t, inf_like(h.t));
    surfaces.push_back({"table", h});
  }
  // Objects, distances uniform in inverse depth over [dmin, 0.9 wall], a little larger than the classic ones.
  const int64_t n_obj = std::uniform_int_distribution<int64_t>(g.objects_min, g.objects_max)(rng);
  add_tabletop_objects(r, n_obj, dmin, 0.9 * wall_z, table, y_t, ObjectPlacement{0.1, 0.35, 0.5}, rng, surfaces, counts);
  const Composite c = zbuffer(surfaces, H, W);
  const torch::Tensor hit = torch::isfinite(c.t);
  const torch::Tensor depth = torch::where(hit, c.t, torch::full_like(c.t, dmax));
  const auto [su, sv] = surface_coordinates(c, r, depth);
  SurfaceMap m;
  m.id = torch::where(hit, c.id, torch::full_like(c.id, -1));
  m.shade = 0.4 + 0.6 * lambert_cosine(c, r);  // one light up-left-front, as in the classic layout
  m.tx = torch::zeros({H, W}, f64), m.ty = torch::zeros({H, W}, f64);
  std::vector<SurfaceLook> looks;
  for (size_t k = 0; k < surfaces.size(); ++k) {
    looks.push_back(draw_look(src, rng));
    const torch::Tensor sel = m.id == int64_t(k);
    const double theta = uni(0, 2 * M_PI), ox = uni(0, 4096), oy = uni(0, 4096);
    const double pix_per_texel = log_uniform(rng, g.texture_scale_min, g.texture_scale_max);
    if (!sel.any().item<bool>()) continue;
    const double z_ref = depth.masked_select(sel).median().item<double>();
    const auto [tx, ty] = texel_coords(su, sv, pix_per_texel * z_ref / r.focal_px, theta, ox, oy);
    m.tx = torch::where(sel, tx, m.tx), m.ty = torch::where(sel, ty, m.ty);
  }
  const torch::Tensor noise = fractal_field(H, W, uni(1.0, 2.0), rng);
  const torch::Tensor materials = fractal_field(H, W, uni(1.2, 2.0), rng);
  const torch::Tensor refl = paint(m, looks, src.textures, noise, materials, L, g.texture_filter == TextureFilter::area);
  std::string objs;
  for (const auto& [k, cnt] : counts) objs += (objs.empty() ? "" : ", ") + std::to_string(cnt) + " " + k + (cnt > 1 ? "s" : "");
  return finish(refl, depth, hit, wavelengths_m,
                std::string("tabletop (textured): wall, ") + (table ? "table, " : "") + std::to_string(n_obj) +
                    " objects (" + (objs.empty() ? "none" : objs) + ")");
}

GeneratedScene generate_dead_leaves_scene(const GeneratorConfig& g, const SceneSources& src,
                                          const std::vector<double>& wavelengths_m, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  auto uni = [&](double a, double b) { return a + (b - a) * U(rng); };
  const int64_t H = g.height_px, W = g.width_px, L = int64_t(wavelengths_m.size());
  const double inv_near = 1.0 / g.depth_min_m, inv_far = 1.0 / g.depth_max_m, range = inv_near - inv_far;
  const double c_stop = 0.9;  // the background fills the rest
  const double rmin = std::max(1.5, g.dead_leaves_min_radius * double(std::min(H, W)));
  const double rmax = std::max(rmin, g.dead_leaves_max_radius * double(std::min(H, W)));
  struct Shape {
    double xc, yc, inv, gx, gy, theta, texel, ox, oy;
  };
  auto plane = [](const auto& s, double x, double y) { return s.inv + s.gx * (x - s.xc) + s.gy * (y - s.yc); };
  // One occlusion process: shapes with radii ∝ r⁻³ on [r_lo, rmax] placed near to far until 90 % is
  // covered, then a slanted background plane; id = the visible shape per pixel.
  auto place = [&](double r_lo, std::vector<Shape>& shapes, std::vector<int32_t>& id) {
    id.assign(size_t(H * W), -1);
    // Per-pixel z-buffer of inverse depth: the nearest shape's plane wins, so a
    // slanted later shape that comes nearer at an edge occludes correctly.
    std::vector<double> best(size_t(H * W), -1.0);
    int64_t covered = 0;
    double inv_prev = inv_near;
    while (double(covered) < c_stop * double(H * W) && int64_t(shapes.size()) < g.dead_leaves_max_shapes) {
      const double cov = double(covered) / double(H * W);
      // Inverse depth from the covered fraction (+ jitter), never nearer than an earlier (occluding) shape.
      const double inv = std::min(inv_prev, inv_near - std::clamp(cov + uni(-0.03, 0.03), 0.0, 1.0) * range);
      inv_prev = inv;
      // Power-law radius p(r) ∝ r^-3 on [rmin, rmax] by inversion.
      const double u = U(rng);
      const double rr = 1.0 / std::sqrt(1.0 / (r_lo * r_lo) - u * (1.0 / (r_lo * r_lo) - 1.0 / (rmax * rmax)));
      const double xc = uni(-0.1 * double(W), 1.1 * double(W)), yc = uni(-0.1 * double(H), 1.1 * double(H));
      const int kind = std::uniform_int_distribution<int>(0, 2)(rng);
      const double ar = uni(0.35, 1.0), rot = uni(0, M_PI);
      // Slant: inverse depth changes by at most 8 % of the range across the shape's radius.
      const double slope = uni(0.0, 0.08) * range / rr, dir = uni(0, 2 * M_PI);
      Shape s{xc, yc, inv, slope * std::cos(dir), slope * std::sin(dir), uni(0, 2 * M_PI),
              log_uniform(rng, g.texture_scale_min, g.texture_scale_max), uni(0, 4096), uni(0, 4096)};
      const double cr = std::cos(rot), sr = std::sin(rot);
      const int64_t x0 = std::max<int64_t>(0, int64_t(std::floor(xc - rr))), x1 = std::min<int64_t>(W - 1, int64_t(std::ceil(xc + rr)));
      const int64_t y0 = std::max<int64_t>(0, int64_t(std::floor(yc - rr))), y1 = std::min<int64_t>(H - 1, int64_t(std::ceil(yc + rr)));
      const int32_t k = int32_t(shapes.size());
      for (int64_t y = y0; y <= y1; ++y)
        for (int64_t x = x0; x <= x1; ++x) {
          const size_t i = size_t(y * W + x);
          const double dx = double(x) + 0.5 - xc, dy = double(y) + 0.5 - yc;
          const double a = (cr * dx + sr * dy) / rr, b = (-sr * dx + cr * dy) / (rr * ar);
          const bool inside = kind == 0 ? (dx * dx + dy * dy <= rr * rr)
                            : kind == 1 ? (a * a + b * b <= 1.0)
                                        : (std::abs(a) <= 0.8 && std::abs(b) <= 0.8);
          if (!inside) continue;
          const double v = std::clamp(plane(s, double(x) + 0.5, double(y) + 0.5), inv_far, inv_near);
          if (id[i] < 0) ++covered;
          if (v > best[i]) best[i] = v, id[i] = k;
        }
      shapes.push_back(s);
    }
    // Background: a slanted plane over the farthest (1 - covered) of the range.
    {
      const double cov = double(covered) / double(H * W);
      const double inv_bg = std::min(inv_prev, inv_far + (1.0 - cov) * range);
      const double dir = uni(0, 2 * M_PI), span = inv_bg - inv_far;
      const double diag = std::sqrt(double(W * W + H * H));
      shapes.push_back({0.5 * double(W), 0.5 * double(H), inv_far + 0.5 * span, span / diag * std::cos(dir),
                        span / diag * std::sin(dir), uni(0, 2 * M_PI), log_uniform(rng, g.texture_scale_min, g.texture_scale_max),
                        uni(0, 4096), uni(0, 4096)});
      const int32_t k = int32_t(shapes.size() - 1);
      const Shape& bg = shapes.back();
      for (int64_t y = 0; y < H; ++y)
        for (int64_t x = 0; x < W; ++x) {  // the background too takes part in the z-buffer
          const size_t i = size_t(y * W + x);
          const double v = std::clamp(plane(bg, double(x) + 0.5, double(y) + 0.5), inv_far, inv_near);
          if (id[i] < 0 || v > best[i]) best[i] = v, id[i] = k;
        }
    }
  };
  std::vector<Shape> shapes;
  std::vector<int32_t> id;
  place(rmin, shapes, id);
  // Optionally, larger surfaces carry the depth and the leaves are markings on them.
  std::vector<Shape> surfaces;
  std::vector<int32_t> sid;
  const bool on_surfaces = g.dead_leaves_surface_min_radius > 0;
  if (on_surfaces) {
    place(std::max(rmin, g.dead_leaves_surface_min_radius * double(std::min(H, W))), surfaces, sid);
    // Each visible (leaf, surface) pair is one painted patch: a leaf crossing a surface edge changes there,
    // as paint ends where an object ends. Its texture geometry is the leaf's, its depth plane the surface's.
    std::map<std::pair<int32_t, int32_t>, int32_t> pair_id;
    std::vector<Shape> patches;
    std::vector<int32_t> pid(size_t(H * W));
    for (size_t i = 0; i < pid.size(); ++i) {
      const auto key = std::make_pair(id[i], sid[i]);
      auto it = pair_id.find(key);
      if (it == pair_id.end()) {
        Shape p = shapes[size_t(id[i])];
        const Shape& q = surfaces[size_t(sid[i])];
        p.ox += q.ox, p.oy += q.oy;  // another part of the photo on another surface
        p.inv = plane(q, p.xc, p.yc), p.gx = q.gx, p.gy = q.gy;
        it = pair_id.emplace(key, int32_t(patches.size())).first;
        patches.push_back(p);
      }
      pid[i] = it->second;
    }
    shapes = std::move(patches);
    id = std::move(pid);
  }
  const int64_t n = int64_t(shapes.size());
  const size_t ns = size_t(n);
  std::vector<double> xc(ns), yc(ns), inv(ns), gx(ns), gy(ns), th(ns), tx(ns), ox(ns), oy(ns);
  std::vector<SurfaceLook> looks;
  for (int64_t k = 0; k < n; ++k) {
    const Shape& s = shapes[size_t(k)];
    xc[size_t(k)] = s.xc, yc[size_t(k)] = s.yc, inv[size_t(k)] = s.inv, gx[size_t(k)] = s.gx, gy[size_t(k)] = s.gy;
    th[size_t(k)] = s.theta, tx[size_t(k)] = s.texel, ox[size_t(k)] = s.ox, oy[size_t(k)] = s.oy;
    looks.push_back(draw_look(src, rng));
  }
  const torch::Tensor idt = torch::tensor(id, torch::kInt32).to(torch::kLong).view({H, W});
  auto per_pixel = [&](const std::vector<double>& v) { return torch::tensor(v, f64).index_select(0, idt.reshape(-1)).view({H, W}); };
  const torch::Tensor X = torch::arange(W, f64).view({1, W}).expand({H, W}) + 0.5;
  const torch::Tensor Y = torch::arange(H, f64).view({H, 1}).expand({H, W}) + 0.5;
  const torch::Tensor DX = X - per_pixel(xc), DY = Y - per_pixel(yc);
  const torch::Tensor invz = (per_pixel(inv) + per_pixel(gx) * DX + per_pixel(gy) * DY).clamp(inv_far, inv_near);
  const torch::Tensor TH = per_pixel(th), TX = per_pixel(tx);
  SurfaceMap m;
  m.id = idt;
  m.tx = (torch::cos(TH) * DX - torch::sin(TH) * DY) / TX + per_pixel(ox);
  m.ty = (torch::sin(TH) * DX + torch::cos(TH) * DY) / TX + per_pixel(oy);
  // A soft light gradient across the frame, as from one lamp.
  const double lx = uni(-0.3, 0.3) / double(W), ly = uni(-0.3, 0.3) / double(H);
  m.shade = (0.85 + lx * (X - 0.5 * double(W)) + ly * (Y - 0.5 * double(H))).clamp(0.4, 1.0);
  const torch::Tensor noise = fractal_field(H, W, uni(1.0, 2.0), rng);
  const torch::Tensor materials = fractal_field(H, W, uni(1.2, 2.0), rng);
  const torch::Tensor refl = paint(m, looks, src.textures, noise, materials, L, g.texture_filter == TextureFilter::area);
  const torch::Tensor valid = torch::ones({H, W}, torch::kBool);
  return finish(refl, 1.0 / invz, valid, wavelengths_m,
                on_surfaces ? "dead leaves: " + std::to_string(surfaces.size() - 1) +
                                  " occluding surfaces and a slanted background, painted with " +
                                  std::to_string(n) + " leaf patches"
                            : "dead leaves: " + std::to_string(n - 1) + " occluding textured shapes and a slanted background");
}

}  // namespace hsd::data
