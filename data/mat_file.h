// MATLAB 5 MAT-files (the "Level 5 MAT-File Format" of MathWorks): the numeric
// arrays and character arrays at the top level of a file, plain or zlib-compressed
// (miCOMPRESSED) elements, little- or big-endian. This is what the measured data
// the generator uses comes in (CAVE cubes, Vrhel et al.'s object spectra, ISETCam's
// reflectance files). Structs, cells, sparse and complex arrays are skipped (their
// names are listed, so a caller can say what the file holds instead).
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <torch/types.h>

namespace hsd::data {

struct MatArray {
  std::vector<int64_t> dims;  // MATLAB's dimensions (rows, cols, ...)
  std::vector<double> values; // column-major, as MATLAB stores them (numeric arrays)
  std::string text;           // character arrays (class mxCHAR), as 8-bit text
  bool is_char = false;
  // The array as float64 with shape `dims` (row-major indexing a[i][j][k] =
  // MATLAB's a(i+1, j+1, k+1)). InputError for a character array.
  torch::Tensor tensor() const;
};

struct MatFile {
  std::map<std::string, MatArray> arrays;  // numeric and character arrays by name
  std::vector<std::string> skipped;        // names of arrays of other classes

  // The named array; InputError naming the file and the variable when missing.
  const MatArray& at(const std::string& name) const;
  std::string path;
};

// Reads a MAT-file; InputError naming the file on anything malformed or
// truncated (every length is checked against what remains).
MatFile read_mat_file(const std::string& path);

}  // namespace hsd::data
