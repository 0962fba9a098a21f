// GDSII stream format writer for the lithography masks (hsd_fabricate): one
// structure (cell) of BOUNDARY elements, one layer per mask. Debian packages
// no C++ library that writes GDSII (libgdsii reads only), so this writes the
// records of the GDSII Stream Format Manual (Calma, release 6.0) directly:
// HEADER 600, BGNLIB, LIBNAME, UNITS, BGNSTR, STRNAME, per polygon BOUNDARY,
// LAYER, DATATYPE 0, XY (closed, 5 points for a rectangle), ENDEL; ENDSTR,
// ENDLIB. Reals are GDSII 8-byte excess-64 base-16 floats; integers big-endian.
// Units: user unit 1 µm, database unit 1 nm (coordinates are integer nm).
// Coordinates: the DOE's own (optics/conventions.h), centred on the grid's
// centre: cell [i, j] of an N×N grid of pitch δ covers
// x ∈ [(j − N/2)δ, (j + 1 − N/2)δ], y ∈ [(i − N/2)δ, (i + 1 − N/2)δ]; GDSII
// viewers draw y up, so they show the DOE seen from the sensor side.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "optics/lithography.h"

namespace hsd::optics {

struct GdsLayer {
  int64_t layer = 1;               // GDSII layer number (0 .. 32767)
  std::vector<CellRect> rects;     // in cells of the grid
};

// The GDSII bytes of `layers` on an n×n grid of pitch_m (a whole number of nm,
// else std::invalid_argument), structure `cell_name`, library `library_name`.
std::vector<char> gdsii_bytes(const std::vector<GdsLayer>& layers, int64_t n, double pitch_m, const std::string& cell_name,
                              const std::string& library_name);

// GDSII 8-byte real of v (excess-64, base 16), big-endian; and its inverse.
void gdsii_real8(double v, unsigned char out[8]);
double gdsii_real8_value(const unsigned char in[8]);

}  // namespace hsd::optics
