#include "data/scene_generator.h"

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
using torch::indexing::None;
using torch::indexing::Slice;
constexpr double kInf = std::numeric_limits<double>::infinity();
const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);

// Periodic 1/f^beta noise [n, n] in [0, 1] (natural images: beta ≈ 1-2 in amplitude).
torch::Tensor pink_noise(int64_t n, double beta, std::mt19937_64& rng) {
  const torch::Tensor k = torch::fft::fftfreq(n, 1.0, f64);
  const torch::Tensor kk = (k.view({n, 1}).pow(2) + k.view({1, n}).pow(2)).sqrt().clamp_min(1.0 / double(n));
  std::vector<double> ph(size_t(n * n));
  std::uniform_real_distribution<double> U(0.0, 2.0 * M_PI);
  for (auto& p : ph) p = U(rng);
  const torch::Tensor phase = torch::tensor(ph, f64).view({n, n});
  const torch::Tensor spec = torch::polar(kk.pow(-beta), phase);
  torch::Tensor x = torch::real(torch::fft::ifft2(spec));
  x = (x - x.min()) / (x.max() - x.min()).clamp_min(1e-12);
  return x;
}

// Bilinear lookup of a periodic texture [n, n] at (u, v) in texture periods.
torch::Tensor sample_periodic(const torch::Tensor& tex, const torch::Tensor& u, const torch::Tensor& v) {
  const int64_t n = tex.size(0);
  const torch::Tensor fu = (u - u.floor()) * double(n), fv = (v - v.floor()) * double(n);
  const torch::Tensor iu = fu.floor().to(torch::kLong), iv = fv.floor().to(torch::kLong);
  const torch::Tensor au = fu - iu.to(torch::kFloat64), av = fv - iv.to(torch::kFloat64);
  const torch::Tensor flat = tex.reshape(-1);
  auto at = [&](const torch::Tensor& a, const torch::Tensor& b) {
    return flat.index_select(0, ((a.remainder(n)) * n + b.remainder(n)).reshape(-1)).view(a.sizes());
  };
  return (1 - av) * ((1 - au) * at(iv, iu) + au * at(iv, iu + 1)) + av * ((1 - au) * at(iv + 1, iu) + au * at(iv + 1, iu + 1));
}

// Texture weight in [0, 1] on the surface coordinates (u, v) [metres].
torch::Tensor texture(const std::string& kind, const torch::Tensor& u, const torch::Tensor& v, double scale_m,
                      std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  if (kind == "flat") return torch::zeros_like(u);
  if (kind == "noise" || kind == "edges") {
    const torch::Tensor tex = pink_noise(128, 1.0 + U(rng), rng);
    const double ph_u = U(rng), ph_v = U(rng);
    torch::Tensor t = sample_periodic(tex, u / (4.0 * scale_m) + ph_u, v / (4.0 * scale_m) + ph_v);
    if (kind == "edges") t = (t > 0.35 + 0.3 * U(rng)).to(torch::kFloat64);
    return t;
  }
  const double period = scale_m * (0.15 + 0.6 * U(rng)), phi = M_PI * U(rng);
  if (kind == "stripes") {
    const torch::Tensor w = (std::cos(phi) * u + std::sin(phi) * v) * (2.0 * M_PI / period);
    return 0.5 + 0.5 * torch::tanh(6.0 * torch::sin(w));
  }
  // checker
  const torch::Tensor a = torch::sin(u * (2.0 * M_PI / period)), b = torch::sin(v * (2.0 * M_PI / period));
  return (a * b > 0).to(torch::kFloat64);
}


}  // namespace

GeneratedScene generate_tabletop_scene(const GeneratorConfig& g, const ReflectanceLibrary& lib,
                                       const std::vector<double>& wavelengths_m, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  auto uni = [&](double a, double b) { return a + (b - a) * U(rng); };
  const int64_t H = g.height_px, W = g.width_px, L = int64_t(wavelengths_m.size());
  const Rays r = make_rays(H, W, g.fov_deg);
  const double dmin = g.depth_min_m, dmax = g.depth_max_m;
  std::vector<Surface> surfaces;
  std::map<std::string, int> counts;

  // Back wall, tilted, its farthest visible point at most dmax.
  const bool wall = U(rng) > 0.2;
  double wall_z = dmax;
  if (wall) {
    const double a = uni(-15, 15) * M_PI / 180, b = uni(-10, 10) * M_PI / 180;
    wall_z = uni(0.85, 1.0) * dmax;
    const Hit h = hit_tilted_wall(r, a, b, &wall_z, dmax);
    surfaces.push_back({"wall", h});
  }
  // Table: the plane y = y_t below the eye, nearest visible point >= dmin.
  const bool table = !wall || U(rng) < 0.8;  // without a wall, a table keeps the scene mostly valid
  const double y_t = uni(1.0, 1.6) * dmin * r.tan_v;
  if (table) {
    Hit h = hit_plane(r, {0, 1, 0}, y_t);
    h.t = torch::where(h.t <= std::min(wall_z * 1.001, dmax), h.t, inf_like(h.t));  // the table ends at the wall (or at dmax)
    surfaces.push_back({"table", h});
  }
  // Objects, distances uniform in inverse depth.
  const int64_t n_obj = std::uniform_int_distribution<int64_t>(g.objects_min, g.objects_max)(rng);
  add_tabletop_objects(r, n_obj, dmin, 0.9 * wall_z, table, y_t, ObjectPlacement{0.08, 0.25, 0.6}, rng, surfaces, counts);

  const Composite c = zbuffer(surfaces, H, W);
  const torch::Tensor hit = torch::isfinite(c.t);
  torch::Tensor depth = torch::where(hit, c.t, torch::full_like(c.t, dmax));
  const auto [su, sv] = surface_coordinates(c, r, depth);
  const torch::Tensor shade = 0.3 + 0.7 * lambert_cosine(c, r);  // one light up-left-front of the scene

  torch::Tensor refl = torch::zeros({L, H, W}, f64);
  const std::vector<std::string> kinds{"flat", "noise", "noise", "stripes", "checker", "edges"};
  std::vector<std::string> used_textures;
  for (size_t k = 0; k < surfaces.size(); ++k) {
    const torch::Tensor sel = (c.id == int64_t(k));
    if (!sel.any().item<bool>()) continue;
    const std::string kind = kinds[std::uniform_int_distribution<size_t>(0, kinds.size() - 1)(rng)];
    const torch::Tensor s1 = lib.draw(rng), s2 = lib.draw(rng);
    const double scale = surfaces[k].what == "wall" || surfaces[k].what == "table" ? 0.3 : 0.08;
    const torch::Tensor t = texture(kind, su, sv, scale, rng);
    const torch::Tensor spec = s1.view({L, 1, 1}) * (1 - t) + s2.view({L, 1, 1}) * t;
    refl = torch::where(sel.unsqueeze(0), spec * shade.unsqueeze(0), refl);
    used_textures.push_back(kind);
  }
  // Background (no wall): a dim neutral, marked invalid.
  refl = torch::where(hit.unsqueeze(0), refl, torch::full_like(refl, 0.05));

  // Structured-light shadows beside near-to-far edges (the far side, to the right).
  torch::Tensor valid = hit.clone();
  if (U(rng) < 0.6) {
    const int64_t w = std::uniform_int_distribution<int64_t>(2, 6)(rng);
    torch::Tensor shadow = torch::zeros_like(valid);
    for (int64_t k = 1; k <= w; ++k)
      shadow.index({Slice(), Slice(k, None)}) |= depth.index({Slice(), Slice(k, None)}) > 1.1 * depth.index({Slice(), Slice(None, W - k)});
    valid = valid & ~shadow;
  }
  GeneratedScene out;
  out.scene.wavelengths_m = wavelengths_m;
  out.scene.kind = SpectralKind::Reflectance;
  out.scene.spectral = refl.clamp(0.0, 1.0).to(torch::kFloat32);
  out.scene.depth_m = depth.to(torch::kFloat32).unsqueeze(0);
  out.scene.mask = valid.to(torch::kFloat32).unsqueeze(0);
  const torch::Tensor dv = depth.masked_select(valid);
  char buf[256];
  std::string objs;
  for (const auto& [k, n] : counts) objs += (objs.empty() ? "" : ", ") + std::to_string(n) + " " + k + (n > 1 ? "s" : "");
  std::snprintf(buf, sizeof buf, "tabletop: %s%s%lld objects (%s); depth %.2f-%.2f m; %.1f %% invalid",
                wall ? "wall, " : "no wall (background invalid), ", table ? "table, " : "", (long long)n_obj,
                objs.empty() ? "none" : objs.c_str(), dv.numel() ? dv.min().item<double>() : 0.0,
                dv.numel() ? dv.max().item<double>() : 0.0, 100.0 * (1.0 - valid.to(torch::kFloat64).mean().item<double>()));
  out.notes = buf;
  return out;
}

GeneratedScene generate_colorchecker_scene(const GeneratorConfig& g, const ReflectanceLibrary& lib,
                                           const std::vector<double>& wavelengths_m,
                                           std::vector<std::array<int64_t, 4>>* boxes) {
  const int64_t H = g.height_px, W = g.width_px, L = int64_t(wavelengths_m.size());
  const double z = g.colorchecker_depth_m;
  // Board: 80 % of the width (or of the height × 1.5), 6 × 4 cells, each patch 80 % of its cell.
  const double board_w = std::min(0.8 * double(W), 0.8 * double(H) * 1.5);
  const double cell = board_w / 6.0, board_h = 4.0 * cell;
  const double x0 = 0.5 * (double(W) - board_w), y0 = 0.5 * (double(H) - board_h);
  torch::Tensor refl = lib.patch("neutral_5").view({L, 1, 1}).expand({L, H, W}).clone();
  torch::Tensor depth = torch::full({H, W}, std::min(g.depth_max_m, std::max(2.0 * z, z + 0.3)), f64);
  const auto board_px = [&](double v) { return int64_t(std::lround(v)); };
  const int64_t bx0 = board_px(x0), bx1 = board_px(x0 + board_w), by0 = board_px(y0), by1 = board_px(y0 + board_h);
  refl.index_put_({Slice(), Slice(by0, by1), Slice(bx0, bx1)}, (lib.patch("black_2") * 0.8).view({L, 1, 1}));
  depth.index_put_({Slice(by0, by1), Slice(bx0, bx1)}, z);
  if (boxes) boxes->clear();
  const auto& names = lib.patch_names();
  for (int64_t i = 0; i < 24; ++i) {
    const int64_t row = i / 6, col = i % 6;
    const double cx0 = x0 + double(col) * cell + 0.1 * cell, cy0 = y0 + double(row) * cell + 0.1 * cell;
    const int64_t px0 = board_px(cx0), px1 = board_px(cx0 + 0.8 * cell), py0 = board_px(cy0), py1 = board_px(cy0 + 0.8 * cell);
    refl.index_put_({Slice(), Slice(py0, py1), Slice(px0, px1)}, lib.patch(names[size_t(i)]).view({L, 1, 1}));
    if (boxes) {  // inner region: a further 15 % margin against blur at the patch edges
      const int64_t m = std::max<int64_t>(1, (px1 - px0) * 15 / 100);
      boxes->push_back({px0 + m, py0 + m, px1 - m, py1 - m});
    }
  }
  GeneratedScene out;
  out.scene.wavelengths_m = wavelengths_m;
  out.scene.kind = SpectralKind::Reflectance;
  out.scene.spectral = refl.to(torch::kFloat32);
  out.scene.depth_m = depth.to(torch::kFloat32).unsqueeze(0);
  out.scene.mask = torch::ones({1, H, W}, torch::kFloat32);
  char buf[160];
  std::snprintf(buf, sizeof buf, "colorchecker: the 24 patches at %.2f m on a dark board, grey wall behind; for spectral evaluation under D65, never for training", z);
  out.notes = buf;
  return out;
}

}  // namespace hsd::data
