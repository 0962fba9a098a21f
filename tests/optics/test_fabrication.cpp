// Fabrication (issue: export a DOE for lithography, tolerance analysis,
// fabrication-aware training): the K-level masks (optics/lithography.h), the
// GDSII writer checked by an independent reader (libGDSII, and gdspy when
// Python has it), the fabricated surface's errors (optics/fabrication_error.h)
// zero at zero size and growing with size on a test DOE, hsd_fabricate as a
// user runs it, and train.fabrication_noise.
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include <libGDSII.h>
#include <opencv2/imgcodecs.hpp>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/config.h"
#include "common/json_reader.h"
#include "common/tensor_io.h"
#include "helpers.h"
#include "optics/doe.h"
#include "optics/fabrication_error.h"
#include "optics/fabrication_tolerance.h"
#include "optics/gdsii.h"
#include "optics/lithography.h"
#include "optics/material.h"
#include "optics/psf.h"
#include "optics/psf_mismatch.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

torch::Tensor uniform_heights(int64_t n, double H, uint64_t seed) {
  auto gen = at::detail::createCPUGenerator(seed);
  return H * at::rand({n, n}, gen, torch::TensorOptions().dtype(torch::kFloat64));
}

// Polygon area by the shoelace formula (x, y interleaved).
double polygon_area(const std::vector<double>& xy) {
  const size_t n = xy.size() / 2;
  double a = 0;
  for (size_t i = 0; i < n; ++i) {
    const size_t j = (i + 1) % n;
    a += xy[2 * i] * xy[2 * j + 1] - xy[2 * j] * xy[2 * i + 1];
  }
  return std::fabs(a) / 2.0;
}

// Layer k + 1 = mask k, as hsd_fabricate numbers them.
std::vector<optics::GdsLayer> gds_layers(const torch::Tensor& masks) {
  std::vector<optics::GdsLayer> layers;
  for (int64_t k = 0; k < masks.size(0); ++k) layers.push_back({k + 1, optics::mask_rectangles(masks[k])});
  return layers;
}

fs::path scratch(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("hsd_test_fab_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

}  // namespace

TEST_CASE("lithography: the binary masks make the K-level map exactly, a full period wraps to level 0", "[fabrication]") {
  const double H = 1.2e-6;
  for (int64_t K : {2, 4, 16, 256}) {
    torch::Tensor h = uniform_heights(40, H, uint64_t(K));
    h[0][0] = H * (1.0 - 0.1 / double(K));  // rounds to K: a full period, no height
    h[0][1] = H * 1.7;                        // outside [0, H): wrapped first
    const optics::LevelMap q = optics::quantize_to_levels(h, H, K);
    const torch::Tensor masks = optics::level_masks(q);
    CHECK(masks.size(0) == int64_t(std::log2(double(K)) + 0.5));
    CHECK(torch::equal(optics::height_from_masks(masks, q.step_m), optics::level_heights(q)));
    CHECK(q.level[0][0].item<int64_t>() == 0);
    CHECK(q.level[0][1].item<int64_t>() == int64_t(std::llround(0.7 * double(K))) % K);
    CHECK(q.level.min().item<int64_t>() >= 0);
    CHECK(q.level.max().item<int64_t>() < K);
    // Each cell's level error is at most half a step (phase-equivalent).
    const torch::Tensor hw = torch::remainder(h, H);
    const torch::Tensor d = torch::remainder(optics::level_heights(q) - hw + H / 2, H) - H / 2;
    CHECK(d.abs().max().item<double>() <= q.step_m / 2 * (1 + 1e-9));
    // Uniform heights: the RMS error is the uniform quantiser's Δ/√12.
    const torch::Tensor u = uniform_heights(256, H, 7);
    const optics::LevelMap qu = optics::quantize_to_levels(u, H, K);
    CHECK(optics::quantisation_rms_m(u, qu, H) == Approx(qu.step_m / std::sqrt(12.0)).epsilon(0.02));
    const auto hist = optics::level_histogram(qu);
    int64_t total = 0;
    for (int64_t c : hist) total += c;
    CHECK(total == 256 * 256);
  }
}

TEST_CASE("lithography: rectangles cover a mask exactly once, features are measured between edges", "[fabrication]") {
  const torch::Tensor mask = uniform_heights(50, 1.0, 3).gt(0.6);
  const auto rects = optics::mask_rectangles(mask);
  torch::Tensor cover = torch::zeros({50, 50}, torch::kInt64);
  for (const auto& r : rects) cover.narrow(0, r.row0, r.rows).narrow(1, r.col0, r.cols).add_(1);
  CHECK(torch::equal(cover, mask.to(torch::kInt64)));
  // Rows merge: a solid block is one rectangle.
  torch::Tensor block = torch::zeros({20, 20}, torch::kBool);
  block.narrow(0, 3, 10).narrow(1, 5, 7).fill_(true);
  REQUIRE(optics::mask_rectangles(block).size() == 1);
  const auto b = optics::mask_rectangles(block)[0];
  CHECK((b.row0 == 3 && b.col0 == 5 && b.rows == 10 && b.cols == 7));
  // A one-cell line, a two-cell space and a wide line inside the grid.
  torch::Tensor m = torch::zeros({12, 30}, torch::kBool);
  m.narrow(1, 4, 1).fill_(true);   // line of 1 cell (columns 4)
  m.narrow(1, 7, 6).fill_(true);   // space of 2 cells (5, 6), then a line of 6
  const optics::MaskFeatures f = optics::mask_features(m, 2.0);
  CHECK(f.min_line_cells == 1);
  CHECK(f.min_space_cells == 2);
  CHECK(f.lines_below == 12);   // the 1-cell line in each of 12 rows
  CHECK(f.spaces_below == 0);   // 2 cells is not below a 2-cell minimum
  CHECK(optics::mask_features(m, 1.0).lines_below == 0);
}

TEST_CASE("GDSII: reals in excess-64 form, and masks read back by libGDSII with their areas", "[fabrication]") {
  // The UNITS record of a file with user unit 1 um and database unit 1 nm
  // (0.001 and 1e-9): the bytes GDSII files carry, up to the last mantissa
  // byte (tools differ there by rounding: KLayout and gdspy truncate).
  unsigned char b[8];
  optics::gdsii_real8(1e-3, b);
  const unsigned char milli[7] = {0x3E, 0x41, 0x89, 0x37, 0x4B, 0xC6, 0xA7};
  CHECK(std::equal(b, b + 7, milli));
  optics::gdsii_real8(1e-9, b);
  const unsigned char nano[7] = {0x39, 0x44, 0xB8, 0x2F, 0xA0, 0x9B, 0x5A};
  CHECK(std::equal(b, b + 7, nano));
  // Decoded independently of gdsii_real8_value: mantissa / 2^56 · 16^(e − 64),
  // within half a unit of the mantissa's last place.
  for (double v : {1e-3, 1e-9, 1.0, -2.5, 0.0625, 3.14159e7, 1e-12}) {
    optics::gdsii_real8(v, b);
    long double mant = 0;
    for (int i = 1; i < 8; ++i) mant = mant * 256 + b[i];
    const int e = (b[0] & 0x7f) - 64;
    const long double x = (b[0] & 0x80 ? -1 : 1) * mant / std::pow(2.0L, 56) * std::pow(16.0L, e);
    CHECK(std::fabs(double(x - v)) <= 0.5 * std::pow(2.0, -56) * std::pow(16.0, e) * (1 + 1e-9));
    CHECK(mant >= std::pow(2.0L, 52));  // normalised: the first hex digit is not 0
    CHECK(optics::gdsii_real8_value(b) == Approx(v).epsilon(1e-15));
  }

  const int64_t N = 48;
  const double pitch = 4e-6;
  const optics::LevelMap q = optics::quantize_to_levels(uniform_heights(N, 1e-6, 11), 1e-6, 8);
  const torch::Tensor masks = optics::level_masks(q);
  const std::vector<optics::GdsLayer> layers = gds_layers(masks);
  const fs::path dir = scratch("gds");
  const std::string file = (dir / "masks.gds").string();
  write_binary_file(file, optics::gdsii_bytes(layers, N, pitch, "HSD_DOE", "HSD"));
  libGDSII::GDSIIData gds(file);
  REQUIRE(gds.ErrMsg == nullptr);
  CHECK(gds.UnitInMeters == Approx(1e-6));
  const iVec found = gds.GetLayers();
  REQUIRE(found.size() == size_t(masks.size(0)));
  for (int64_t k = 0; k < masks.size(0); ++k) {
    CHECK(found[size_t(k)] == k + 1);
    const PolygonList polys = gds.GetPolygons(int(k + 1));
    double area_um2 = 0;
    for (const dVec& p : polys) area_um2 += polygon_area(p);
    const double mask_um2 = masks[k].sum().item<double>() * (pitch * 1e6) * (pitch * 1e6);
    CHECK(area_um2 == Approx(mask_um2).epsilon(1e-12));
    CHECK(polys.size() == layers[size_t(k)].rects.size());
  }
  // Centred: the polygons' bounding box is inside ±N·pitch/2.
  double lo = 1e9, hi = -1e9;
  for (const dVec& p : gds.GetPolygons(1))
    for (double v : p) lo = std::min(lo, v), hi = std::max(hi, v);
  CHECK(lo >= -double(N) * pitch * 1e6 / 2 - 1e-9);
  CHECK(hi <= double(N) * pitch * 1e6 / 2 + 1e-9);
  fs::remove_all(dir);
}

TEST_CASE("GDSII: gdspy (a second independent reader) finds the layers and the masks' areas", "[fabrication]") {
  // Debian's python3-gdspy lives in the system interpreter's dist-packages.
  if (test::capture("/usr/bin/python3 -c 'import gdspy' 2>/dev/null").second != 0) {
    WARN("python3-gdspy is not installed (scripts/setup.sh installs it): the libGDSII check above stands alone");
    return;
  }
  const int64_t N = 32;
  const optics::LevelMap q = optics::quantize_to_levels(uniform_heights(N, 1e-6, 5), 1e-6, 4);
  const torch::Tensor masks = optics::level_masks(q);
  const std::vector<optics::GdsLayer> layers = gds_layers(masks);
  const fs::path dir = scratch("gdspy");
  const std::string file = (dir / "masks.gds").string();
  write_binary_file(file, optics::gdsii_bytes(layers, N, 8e-6, "MYCELL", "HSD"));
  const std::string py =
      "import gdspy, sys\n"
      "lib = gdspy.GdsLibrary(infile='" + file + "')\n"
      "c = lib.cell_dict['MYCELL']\n"
      "a = c.get_polygons(by_spec=True)\n"
      "print(lib.unit, lib.precision, len(a), *[f'{k[0]}:{sum(abs(gdspy.Polygon(p).area()) for p in v):.6f}' for k, v in sorted(a.items())])\n";
  std::ofstream(dir / "read.py") << py;
  const auto [out, code] = test::capture("/usr/bin/python3 " + (dir / "read.py").string() + " 2>&1");
  INFO(out);
  REQUIRE(code == 0);
  std::istringstream is(out);
  double unit = 0, precision = 0;
  size_t n_layers = 0;
  is >> unit >> precision >> n_layers;
  CHECK(unit == Approx(1e-6));
  CHECK(precision == Approx(1e-9));
  CHECK(n_layers == size_t(masks.size(0)));
  for (int64_t k = 0; k < masks.size(0); ++k) {
    std::string tok;
    is >> tok;
    const auto colon = tok.find(':');
    CHECK(std::stoi(tok.substr(0, colon)) == k + 1);
    CHECK(std::stod(tok.substr(colon + 1)) == Approx(masks[k].sum().item<double>() * 64.0).epsilon(1e-9));
  }
  fs::remove_all(dir);
}

TEST_CASE("fabricated surface: whole-cell refinement, exact and interpolated shifts with zeros moving in", "[fabrication]") {
  const torch::Tensor h = uniform_heights(6, 1e-6, 2);
  const torch::Tensor r = optics::refine_cells(h, 3);
  CHECK(r.size(0) == 18);
  CHECK(r[4][7].item<double>() == h[1][2].item<double>());
  const torch::Tensor s = optics::shift_map(r, 2.0, -1.0);
  CHECK(s[6][6].item<double>() == r[4][7].item<double>());
  CHECK(torch::all(s.narrow(0, 0, 2) == 0).item<bool>());
  CHECK(torch::all(s.narrow(1, 17, 1) == 0).item<bool>());
  const torch::Tensor f = optics::shift_map(r, 0.0, 0.25);
  CHECK(f[5][9].item<double>() == Approx(0.75 * r[5][9].item<double>() + 0.25 * r[5][8].item<double>()));
  CHECK(torch::equal(optics::shift_map(r, 0.0, 0.0), r));
}

TEST_CASE("fabricated surface: each error is zero at zero size and its PSF change grows with size on a test DOE", "[fabrication][psf]") {
  Config cfg = load_config(test::source_path("configs/tiny.json"), {});
  const auto material = optics::Material::load(cfg.optics.material);
  const optics::Doe doe = optics::make_doe(cfg.optics, material, 0, torch::kCPU);
  const double H = doe.max_height_m();
  const int64_t s = 4, N = cfg.optics.doe_samples;
  const optics::LevelMap q = optics::quantize_to_levels(doe.height().detach(), H, 16);
  const torch::Tensor hq = optics::level_heights(q);
  OpticsConfig fine = cfg.optics;
  fine.doe_samples = N * s;
  fine.doe_pitch_m = cfg.optics.doe_pitch_m / double(s);
  const optics::PsfSimulator sim(optics::make_psf_spec(fine, material, torch::kCPU));
  const optics::FabricationProcess process{cfg.optics.doe_pitch_m, s, H, 16, 0.0};
  const torch::Tensor ref_surface = optics::refine_cells(hq, s);
  CHECK(torch::equal(optics::fabricated_surface(hq, {}, process, 0), ref_surface));
  torch::NoGradGuard no_grad;
  const torch::Tensor ref = sim.compute(ref_surface).psf.to(torch::kFloat64);
  // The refined grid renders the same DOE: its PSFs equal the DOE grid's.
  const optics::PsfSimulator coarse(optics::make_psf_spec(cfg.optics, material, torch::kCPU));
  const torch::Tensor ref_coarse = coarse.compute(hq).psf.to(torch::kFloat64);
  CHECK(optics::compare_psfs(ref, ref_coarse).rel_l1.max().item<double>() < 0.02);

  FabricationToleranceConfig T;
  T.height_scale_error = {0.0, 0.05, 0.1, 0.2};
  T.roughness_rms_m = {0.0, 10e-9, 20e-9, 40e-9};
  T.roughness_correlation_m = 16e-6;
  T.misalignment_m = {0.0, 1e-6, 2e-6, 4e-6};
  T.edge_blur_m = {0.0, 1e-6, 2e-6, 4e-6};
  T.decentre_m = {0.0, 8e-6, 16e-6, 32e-6};
  for (const auto& sw : optics::tolerance_sweeps(T)) {
    std::vector<double> change;
    for (double size : sw.sizes) {
      const torch::Tensor surface = optics::fabricated_surface(hq, optics::tolerance_error(sw, size, T), process, 9);
      if (size == 0.0) CHECK(torch::equal(surface, ref_surface));
      change.push_back(optics::compare_psfs(sim.compute(surface).psf.to(torch::kFloat64), ref).rel_l1.mean().item<double>());
    }
    INFO(sw.name << ": " << change[0] << " " << change[1] << " " << change[2] << " " << change[3]);
    CHECK(change[0] == 0.0);
    for (size_t i = 1; i < change.size(); ++i) CHECK(change[i] > change[i - 1]);
  }
}

TEST_CASE("fabrication noise: a zero scale draws no error, draws are seeded, and the gradient through the errors matches central differences (float64)", "[fabrication]") {
  std::mt19937_64 rng(3);
  double angle = -1;
  CHECK(optics::no_fabrication_error(optics::draw_fabrication_error({}, rng, &angle)));
  CHECK((angle >= 0 && angle < 2 * M_PI));
  FabricationErrorConfig scales;
  scales.height_scale_error = 0.05, scales.edge_blur_m = 4e-6, scales.decentre_m = 16e-6, scales.roughness_rms_m = 10e-9;
  std::mt19937_64 a(7), b(7);
  const auto ea = optics::draw_fabrication_error(scales, a, nullptr), eb = optics::draw_fabrication_error(scales, b, nullptr);
  CHECK(ea.height_scale_error == eb.height_scale_error);
  CHECK((ea.edge_blur_m >= 0 && ea.edge_blur_m <= 4e-6));
  CHECK((ea.decentre_m >= 0 && ea.decentre_m <= 16e-6));
  CHECK(ea.misalignment_m == 0.0);
  // The curriculum's scaled scales (train.fabrication_noise_ramp_steps) draw the same errors scaled.
  std::mt19937_64 c(7);
  const auto ec = optics::draw_fabrication_error(optics::scaled_fabrication_error(scales, 0.25), c, nullptr);
  CHECK(ec.height_scale_error == Approx(0.25 * ea.height_scale_error).epsilon(1e-12));
  CHECK(ec.edge_blur_m == Approx(0.25 * ea.edge_blur_m).epsilon(1e-12));
  CHECK(ec.decentre_m == Approx(0.25 * ea.decentre_m).epsilon(1e-12));
  CHECK(ec.roughness_rms_m == Approx(0.25 * ea.roughness_rms_m).epsilon(1e-12));
  CHECK(optics::no_fabrication_error(optics::scaled_fabrication_error(scales, 0.0)));
  // Training differentiates through the errors (trainer.cpp): blur, scale and
  // a sub-cell decentre are linear in the map, roughness adds to it.
  FabricationErrorConfig e;
  e.height_scale_error = 0.07, e.edge_blur_m = 9e-6, e.decentre_m = 11e-6, e.roughness_rms_m = 10e-9;
  const optics::FabricationProcess p{8e-6, 1, 2e-6, 0, 0.3};
  const torch::Tensor h0 = 1e-6 + uniform_heights(16, 1e-6, 1);
  const torch::Tensor w = uniform_heights(16, 1.0, 2);
  auto loss = [&](const torch::Tensor& h) { return (w * optics::fabricated_surface(h, e, p, 5)).sum(); };
  const torch::Tensor h = h0.clone().requires_grad_();
  loss(h).backward();
  REQUIRE(h.grad().defined());
  CHECK(!torch::equal(h.grad(), w));  // not the identity (a straight-through gradient would be w)
  for (uint64_t k = 0; k < 3; ++k) {
    const torch::Tensor v = uniform_heights(16, 1.0, 10 + k) - 0.5;
    const double eps = 1e-9;
    const double fd = (loss(h0 + eps * v) - loss(h0 - eps * v)).item<double>() / (2 * eps);
    CHECK((h.grad() * v).sum().item<double>() == Approx(fd).epsilon(1e-6));
  }
}

TEST_CASE("hsd_fabricate: PNG, TIFF and GDSII of a DOE, masks rebuild its levels, small features flagged, the tolerance sweep", "[fabrication][app]") {
  const fs::path dir = scratch("app");
  const std::string cfg = "--config configs/tiny.json";
  // A Fresnel DOE as a height-map file.
  const test::Run h = test::run("hsd_fabricate " + cfg + " --doe /nonexistent/doe.pt --out " + (dir / "x").string());
  CHECK(h.code == 2);
  CHECK(h.err.find("/nonexistent/doe.pt") != std::string::npos);
  Config c = load_config(test::source_path("configs/tiny.json"), {});
  const auto material = optics::Material::load(c.optics.material);
  const optics::Doe doe = optics::make_doe(c.optics, material, 0, torch::kCPU);
  const std::string doe_file = (dir / "doe.pt").string();
  optics::save_height_file(doe_file, doe.height().detach(), c.optics.doe_pitch_m);
  const test::Run bad = test::run("hsd_fabricate " + cfg + " --set fabrication.levels=12 --doe " + doe_file + " --out " + (dir / "x").string());
  CHECK(bad.code == 2);
  CHECK(bad.err.find("fabrication.levels") != std::string::npos);

  const std::string out = (dir / "fab").string();
  const test::Run r = test::run("hsd_fabricate " + cfg + " --set fabrication.levels=8 --set fabrication.min_feature_m=2e-05 --doe " +
                                doe_file + " --tolerance --set fabrication.tolerance.height_scale_error=[0,0.1]"
                                " --set fabrication.tolerance.roughness_rms_m=[0,2e-08] --set fabrication.tolerance.misalignment_m=[0,2e-06]"
                                " --set fabrication.tolerance.edge_blur_m=[0,2e-06] --set fabrication.tolerance.decentre_m=[0,1.6e-05]"
                                " --set fabrication.tolerance.subsamples=2 --set fabrication.tolerance.draws=3 --out " + out);
  INFO(r.err);
  REQUIRE(r.code == 0);
  for (const char* f : {"height_map.png", "height_map.tif", "height_map.json", "mask_0.png", "mask_1.png", "mask_2.png", "masks.gds",
                        "fabrication.json", "fabrication.md", "fabrication.png", "tolerance.json", "tolerance.md", "tolerance.png", "config.json"})
    CHECK(fs::exists(fs::path(out) / f));
  CHECK(!fs::exists(fs::path(out) / "mask_3.png"));
  const Json side = Json::parse(read_text_file(out + "/height_map.json"));
  const Json rep = Json::parse(read_text_file(out + "/fabrication.json"));
  const double H = side["max_height_m"].get<double>();
  CHECK(H == Approx(doe.max_height_m()));
  CHECK(side["pitch_m"].get<double>() == Approx(8e-6));
  CHECK(rep["levels"].get<int64_t>() == 8);
  // The PNG masks rebuild the 8-level map of the DOE.
  const optics::LevelMap q = optics::quantize_to_levels(doe.height().detach(), H, 8);
  torch::Tensor level = torch::zeros_like(q.level);
  double mask_area = 0;
  for (int k = 0; k < 3; ++k) {
    const cv::Mat m = cv::imread(out + "/mask_" + std::to_string(k) + ".png", cv::IMREAD_UNCHANGED);
    REQUIRE(m.type() == CV_8U);
    const torch::Tensor t = torch::from_blob(m.data, {m.rows, m.cols}, torch::kUInt8).clone();
    CHECK(torch::all((t == 0) | (t == 255)).item<bool>());
    level += t.gt(0).to(torch::kInt64) * (int64_t(1) << k);
    if (k == 0) mask_area = t.gt(0).sum().item<double>() * 64.0;  // µm²
  }
  CHECK(torch::equal(level, q.level));
  // 16-bit height map: the design's heights within one count.
  const cv::Mat hm = cv::imread(out + "/height_map.png", cv::IMREAD_UNCHANGED);
  REQUIRE(hm.type() == CV_16U);
  cv::Mat hm32;
  hm.convertTo(hm32, CV_32F);
  const torch::Tensor ht = torch::from_blob(hm32.data, {hm.rows, hm.cols}, torch::kFloat32).to(torch::kFloat64) / 65535.0 * H;
  CHECK((ht - doe.height().detach()).abs().max().item<double>() <= H / 65535.0);
  const cv::Mat tif = cv::imread(out + "/height_map.tif", cv::IMREAD_UNCHANGED);
  CHECK(cv::norm(tif, hm, cv::NORM_INF) == 0.0);
  // The GDSII layer 1 holds mask 0's area.
  libGDSII::GDSIIData gds(out + "/masks.gds");
  REQUIRE(gds.ErrMsg == nullptr);
  CHECK(gds.GetLayers().size() == 3);
  double a = 0;
  for (const dVec& p : gds.GetPolygons(1)) a += polygon_area(p);
  CHECK(a == Approx(mask_area).epsilon(1e-12));
  // 20 µm is 2.5 cells: the Fresnel zones' 1- and 2-cell features are flagged.
  CHECK(rep["features_below_min"].get<int64_t>() > 0);
  CHECK(rep["min_feature_m"].get<double>() == Approx(8e-6));
  CHECK(rep["quantisation_rms_m"].get<double>() > 0);
  CHECK(read_text_file(out + "/fabrication.md").find("(flagged)") != std::string::npos);
  // The sweep: zero at zero size, a change at the other.
  const Json tol = Json::parse(read_text_file(out + "/tolerance.json"));
  REQUIRE(tol["sweeps"].size() == 6);
  for (const Json& sw : tol["sweeps"]) {
    INFO(sw["kind"].get<std::string>());
    CHECK(sw["psf_rel_l1_mean"][0].get<double>() == 0.0);
    CHECK(sw["psf_rel_l1_mean"][1].get<double>() > 1e-4);
    CHECK(std::isfinite(sw["crlb_aggregate"][1].get<double>()));
  }
  // The random draws: each a change, each of its own size, within the scales.
  const Json& draws = tol["draws"]["rows"];
  REQUIRE(draws.size() == 3);
  for (const Json& d : draws) {
    CHECK(d["psf_rel_l1_mean"].get<double>() > 1e-4);
    CHECK(d["edge_blur_m"].get<double>() >= 0.0);
    CHECK(d["edge_blur_m"].get<double>() <= 8e-6);
    CHECK(d["decentre_m"].get<double>() == 0.0);
  }
  CHECK(draws[0]["height_scale_error"] != draws[1]["height_scale_error"]);
  CHECK(tol["draws"]["psf_rel_l1_mean"]["sd"].get<double>() > 0.0);
  // Another run's seed meets the same draws (they are seeded by their index alone).
  const std::string out2 = (dir / "fab2").string();
  const test::Run r2 = test::run("hsd_fabricate " + cfg + " --set seed=7 --set fabrication.levels=8 --doe " + doe_file +
                                 " --tolerance --set fabrication.tolerance.draws=3 --set fabrication.tolerance.subsamples=2" +
                                 " --set fabrication.tolerance.height_scale_error=[0] --set fabrication.tolerance.roughness_rms_m=[0]" +
                                 " --set fabrication.tolerance.misalignment_m=[0] --set fabrication.tolerance.edge_blur_m=[0]" +
                                 " --set fabrication.tolerance.decentre_m=[0] --out " + out2);
  INFO(r2.err);
  REQUIRE(r2.code == 0);
  const Json tol2 = Json::parse(read_text_file(out2 + "/tolerance.json"));
  REQUIRE(tol2["draws"]["rows"].size() == 3);
  for (size_t d = 0; d < 3; ++d) {
    CHECK(tol2["draws"]["rows"][d]["height_scale_error"] == draws[d]["height_scale_error"]);
    CHECK(tol2["draws"]["rows"][d]["edge_blur_m"] == draws[d]["edge_blur_m"]);
  }
  fs::remove_all(dir);
}

TEST_CASE("train.fabrication_noise: the same run sees other PSFs in training, validates the design, ramps up, and refuses a misalignment", "[fabrication][app]") {
  const fs::path base = scratch("train");
  const std::string sets = test::tiny_run_sets(base / "data") + " --set train.log_every=1";
  const std::string cfg = "--config configs/tiny.json" + sets;
  const std::string noise = " --set train.fabrication_noise.height_scale_error=0.2 --set train.fabrication_noise.edge_blur_m=8e-06";
  REQUIRE(test::run("hsd_train " + cfg + " --out " + (base / "a").string()).code == 0);
  const test::Run b = test::run("hsd_train " + cfg + noise + " --out " + (base / "b").string());
  INFO(b.err);
  REQUIRE(b.code == 0);
  // Row 1 is step 0's validation, then the steps.
  const auto column = test::csv_column;
  const auto ta = column(base / "a/metrics.csv", "train_loss"), tb = column(base / "b/metrics.csv", "train_loss");
  const auto va = column(base / "a/metrics.csv", "val_loss"), vb = column(base / "b/metrics.csv", "val_loss");
  REQUIRE(ta.size() >= 2);
  REQUIRE(tb.size() == ta.size());
  // Step 0's validation is the same design in both runs; its training loss is not.
  CHECK(va[0] == vb[0]);
  CHECK(std::isfinite(tb[1]));
  CHECK(ta[1] != tb[1]);
  // The curriculum: at step 0 the ramp's scale is 0, so the first step is the nominal run's; the next is not.
  const test::Run r = test::run("hsd_train " + cfg + noise + " --set train.fabrication_noise_ramp_steps=2 --out " +
                                (base / "r").string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto tr = column(base / "r/metrics.csv", "train_loss");
  REQUIRE(tr.size() == ta.size());
  CHECK(tr[1] == ta[1]);
  CHECK(tr[2] != ta[2]);
  const test::Run bad_ramp = test::run("hsd_train " + cfg + " --set train.fabrication_noise_ramp_steps=-1 --out " + (base / "d").string());
  CHECK(bad_ramp.code == 2);
  CHECK(bad_ramp.err.find("train.fabrication_noise_ramp_steps") != std::string::npos);
  const test::Run bad = test::run("hsd_train " + cfg + " --set train.fabrication_noise.misalignment_m=1e-06 --out " + (base / "c").string());
  CHECK(bad.code == 2);
  CHECK(bad.err.find("train.fabrication_noise.misalignment_m") != std::string::npos);
  // A calibrated camera: trained with the pre-inversion built from each draw's
  // PSFs, then swept with and without fabrication.tolerance.calibrated. The
  // design without error is the same system either way; under the draws the
  // network's inputs differ, and so do its scores.
  const std::string wcfg = cfg + " --set model.preinverse=\"wiener\"" + noise + " --set train.fabrication_noise_calibrated=true";
  const test::Run w = test::run("hsd_train " + wcfg + " --out " + (base / "w").string());
  INFO(w.err);
  REQUIRE(w.code == 0);
  auto sweep = [&](const std::string& calibrated, const std::string& out) {
    const test::Run f = test::run("hsd_fabricate " + wcfg + " --doe " + (base / "w/checkpoints/last.pt").string() +
                                  " --tolerance --set fabrication.tolerance.draws=2 --set fabrication.tolerance.subsamples=2"
                                  " --set fabrication.tolerance.height_scale_error=[0] --set fabrication.tolerance.roughness_rms_m=[0]"
                                  " --set fabrication.tolerance.misalignment_m=[0] --set fabrication.tolerance.edge_blur_m=[0]"
                                  " --set fabrication.tolerance.decentre_m=[0] --set fabrication.tolerance.calibrated=" +
                                  calibrated + " --out " + (base / out).string());
    INFO(f.err);
    REQUIRE(f.code == 0);
    return Json::parse(read_text_file((base / out / "tolerance.json").string()));
  };
  const Json as_trained = sweep("false", "tol_design"), calibrated = sweep("true", "tol_calibrated");
  CHECK_FALSE(as_trained["calibrated"].get<bool>());
  CHECK(calibrated["calibrated"].get<bool>());
  CHECK(calibrated["design"]["hs_psnr_db"].get<double>() == as_trained["design"]["hs_psnr_db"].get<double>());
  CHECK(calibrated["design"]["depth_rmse_m"].get<double>() == as_trained["design"]["depth_rmse_m"].get<double>());
  REQUIRE(calibrated["draws"]["rows"].size() == 2);
  for (size_t d = 0; d < 2; ++d) {
    INFO("draw " << d);
    CHECK(calibrated["draws"]["rows"][d]["psf_rel_l1_mean"] == as_trained["draws"]["rows"][d]["psf_rel_l1_mean"]);  // the same surfaces
    CHECK(calibrated["draws"]["rows"][d]["hs_psnr_db"].get<double>() != as_trained["draws"]["rows"][d]["hs_psnr_db"].get<double>());
  }
  fs::remove_all(base);
}
