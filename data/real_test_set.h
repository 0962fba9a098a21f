// The held-out real-derived test set (hsd_scenes --real): scenes that training
// never sees, built from real captures.
//   * The CAVE "balloons" cube (Yasuma et al. 2010; 101 x 101 pixels, 31 bands
//     400-700 nm, relative reflectance; data/real/cave_balloons/) band-integrated
//     onto the config's bands and mapped onto planes seen by the generator's
//     pinhole camera: fronto-parallel at several depths and slanted (30-45°
//     about the vertical or the horizontal axis) across the depth range. The
//     frame is 202 x 202 pixels (2 per cube pixel: the cube was reduced from
//     512 px by its publisher, and stretching it over a 512-px frame left it
//     blurred, power-spectrum slope -4.8), with the field of view cut so a
//     pixel subtends the generator's angle; the cube fills the frame at the
//     plane's reference depth and is mirrored beyond its edges (slanted planes),
//     so every pixel is a real measured spectrum. Real spectra and real
//     texture; the geometry is synthetic (CAVE has no depth).
//   * The Middlebury 2006 "Aloe" photograph with its ground-truth disparity
//     (data/real/middlebury2006_aloe/, data/rgbd_import.h): real geometry and
//     texture; its spectra are lifted from RGB (one spectrum per colour).
// No CAVE or Middlebury data is used by the training generator.
#pragma once
#include <string>
#include <vector>

#include "common/config.h"
#include "data/manifest.h"
#include "data/realism_stats.h"
#include "data/scene_exr.h"

namespace hsd::data {

// data/real/cave_balloons/balloons_101_101_31.mat
std::string cave_balloons_path();
// The cube as a reflectance scene on the given bands: spectral [L, 101, 101],
// depth 1 m (CAVE has none), mask all valid. InputError naming the file.
SpectralScene load_cave_balloons(const std::vector<double>& wavelengths_m, double band_width_m);
// The realism statistics of the cube (no depth histogram): the reference row.
SceneRealism cave_realism(const RealismSpec& spec);

// Writes the set into `dir` (created): cave_*.exr and aloe.exr, previews,
// manifest.json (every scene in the test split) and realism.json/.md. Returns the manifest.
Manifest generate_real_test_set(const Config& cfg, const std::string& dir);

}  // namespace hsd::data
