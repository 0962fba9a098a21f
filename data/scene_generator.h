// Synthetic HS-D scenes that look like the paper's benchtop captures, made by
// ray casting (one ray per pixel, pinhole camera at the origin looking along
// +z, x right, y down, so rows grow downward as in the image):
//   * a back wall (tilted up to ±15°; absent in 20 % of scenes, leaving
//     background pixels that the mask marks invalid), a table plane below the
//     camera (in 80 %, always when there is no wall), and objects_min..objects_max objects: spheres, boxes
//     rotated about the vertical, vertical cylinders with a top cap, and
//     slanted rectangular cards, standing on the table or floating, their
//     distances drawn uniformly in inverse depth over [depth_min, wall];
//   * true occlusions from the nearest hit per ray; Z = distance along the axis;
//   * textures from reflectance pairs (reflectance_library.h) blended by flat,
//     1/f-noise (natural-image-like power spectrum), stripe, checker or
//     hard-edged noise patterns in surface coordinates;
//   * Lambertian shading under one light (factor 0.3-1.0) folded into the
//     stored reflectance, as measured reflectance of real scenes includes it;
//   * structured-light-like shadows: in 60 % of scenes a 2-6 px band beside
//     every near-to-far depth edge is marked invalid, as a projector offset
//     to the side leaves it unlit.
// Deterministic for a seed. The generator's field of view (data.generator.fov_deg)
// is its own: the scenes are images plus depth maps, not tied to the optics.
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "common/config.h"
#include "data/reflectance_library.h"
#include "data/scene_exr.h"

namespace hsd::data {

struct GeneratedScene {
  SpectralScene scene;  // reflectance, on the library's bands
  std::string notes;    // one line: what is in it
};

GeneratedScene generate_tabletop_scene(const GeneratorConfig& g, const ReflectanceLibrary& lib,
                                       const std::vector<double>& wavelengths_m, uint64_t seed);

// The 24 ColorChecker patches (6 × 4, the chart's order, row-major from
// dark_skin to black_2) on a dark board facing the camera at
// g.colorchecker_depth_m, in front of a grey wall at g.depth_max_m; no shading
// (the stored values are the patches' reflectances). `boxes` receives each
// patch's inner region [x0, y0, x1, y1) (pixels, margins excluded) for
// evaluation.
GeneratedScene generate_colorchecker_scene(const GeneratorConfig& g, const ReflectanceLibrary& lib,
                                           const std::vector<double>& wavelengths_m,
                                           std::vector<std::array<int64_t, 4>>* boxes);

}  // namespace hsd::data
