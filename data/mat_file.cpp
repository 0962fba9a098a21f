#include "data/mat_file.h"

#include <cstring>
#include <fstream>
#include <iterator>

#include <torch/torch.h>
#include <zlib.h>

#include "common/error.h"

namespace hsd::data {

namespace {

// Data types of the format's tags (miINT8 ... miUTF32).
enum : uint32_t {
  miINT8 = 1, miUINT8 = 2, miINT16 = 3, miUINT16 = 4, miINT32 = 5, miUINT32 = 6, miSINGLE = 7, miDOUBLE = 9,
  miINT64 = 12, miUINT64 = 13, miMATRIX = 14, miCOMPRESSED = 15, miUTF8 = 16, miUTF16 = 17, miUTF32 = 18
};
// Array classes (mxCELL_CLASS ... mxUINT64_CLASS).
enum : uint32_t { mxCHAR = 4, mxDOUBLE = 6, mxUINT64 = 15 };

constexpr size_t kMaxInflated = size_t(1) << 30;  // 1 GiB: a guard against a doctored length or a zip bomb
constexpr int64_t kMaxElements = int64_t(1) << 27;  // 1 GiB as doubles

struct Reader {
  const uint8_t* p;
  size_t n, pos = 0;
  bool swap;
  const std::string& file;

  [[noreturn]] void fail(const std::string& what) const { input_error(file, "malformed MAT-file: " + what); }
  size_t left() const { return n - pos; }
  uint32_t u32(size_t at) const {
    uint32_t v;
    std::memcpy(&v, p + at, 4);
    return swap ? __builtin_bswap32(v) : v;
  }
};

size_t type_size(uint32_t t) {
  switch (t) {
    case miINT8: case miUINT8: case miUTF8: return 1;
    case miINT16: case miUINT16: case miUTF16: return 2;
    case miINT32: case miUINT32: case miSINGLE: case miUTF32: return 4;
    case miDOUBLE: case miINT64: case miUINT64: return 8;
    default: return 0;
  }
}

template <typename T>
T load(const uint8_t* q, bool swap) {
  T v;
  std::memcpy(&v, q, sizeof(T));
  if (swap) {
    uint8_t b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
    std::memcpy(&v, b, sizeof(T));
  }
  return v;
}

double element_value(uint32_t type, const uint8_t* q, bool swap) {
  switch (type) {
    case miINT8: return double(load<int8_t>(q, swap));
    case miUINT8: case miUTF8: return double(load<uint8_t>(q, swap));
    case miINT16: return double(load<int16_t>(q, swap));
    case miUINT16: case miUTF16: return double(load<uint16_t>(q, swap));
    case miINT32: return double(load<int32_t>(q, swap));
    case miUINT32: case miUTF32: return double(load<uint32_t>(q, swap));
    case miSINGLE: return double(load<float>(q, swap));
    case miDOUBLE: return load<double>(q, swap);
    case miINT64: return double(load<int64_t>(q, swap));
    case miUINT64: return double(load<uint64_t>(q, swap));
    default: return 0.0;
  }
}

// One tagged element at r.pos: its type and a view of its bytes; advances past
// it (with the 8-byte padding of regular elements; none after compressed ones).
struct Element {
  uint32_t type;
  const uint8_t* data;
  size_t bytes;
};
Element next_element(Reader& r) {
  if (r.left() < 8) r.fail("truncated tag at byte " + std::to_string(r.pos));
  const uint32_t first = r.u32(r.pos);
  if ((first >> 16) != 0) {  // small data element: 2-byte size, 2-byte type, 4 bytes of data
    const uint32_t bytes = first >> 16, type = first & 0xFFFF;
    if (bytes > 4) r.fail("small element of " + std::to_string(bytes) + " bytes");
    Element e{type, r.p + r.pos + 4, bytes};
    r.pos += 8;
    return e;
  }
  const uint32_t bytes = r.u32(r.pos + 4);
  if (bytes > r.left() - 8) r.fail("element of " + std::to_string(bytes) + " bytes at byte " + std::to_string(r.pos) + " runs past the end");
  Element e{first, r.p + r.pos + 8, bytes};
  size_t advance = 8 + size_t(bytes);
  if (first != miCOMPRESSED) advance = (advance + 7) / 8 * 8;
  r.pos = std::min(r.n, r.pos + advance);
  return e;
}

std::vector<uint8_t> inflate_all(const Element& e, const std::string& file) {
  std::vector<uint8_t> out;
  z_stream zs{};
  if (inflateInit(&zs) != Z_OK) input_error(file, "zlib could not start");
  zs.next_in = const_cast<Bytef*>(e.data);
  zs.avail_in = uInt(e.bytes);
  int ret = Z_OK;
  while (ret != Z_STREAM_END) {
    if (out.size() >= kMaxInflated) break;
    const size_t old = out.size();
    out.resize(std::min(kMaxInflated, old + std::max<size_t>(1 << 16, old)));
    zs.next_out = out.data() + old;
    zs.avail_out = uInt(out.size() - old);
    ret = inflate(&zs, Z_NO_FLUSH);
    out.resize(out.size() - zs.avail_out);
    if (ret == Z_STREAM_END) break;
    if (ret != Z_OK) {
      inflateEnd(&zs);
      input_error(file, "malformed MAT-file: a compressed element does not inflate (zlib error " + std::to_string(ret) + ")");
    }
    if (zs.avail_in == 0 && ret == Z_OK && zs.avail_out != 0) {
      inflateEnd(&zs);
      input_error(file, "malformed MAT-file: a compressed element is truncated");
    }
  }
  inflateEnd(&zs);
  if (ret != Z_STREAM_END) input_error(file, "malformed MAT-file: a compressed element inflates past 1 GiB");
  return out;
}

// The contents of one miMATRIX element.
void read_matrix(const Element& m, bool swap, const std::string& file, MatFile& out) {
  Reader r{m.data, m.bytes, 0, swap, file};
  if (m.bytes == 0) return;  // an empty array
  const Element flags = next_element(r);
  if (flags.type != miUINT32 || flags.bytes != 8) r.fail("array flags");
  const uint32_t cls = load<uint32_t>(flags.data, swap) & 0xFF;
  const bool complex = (load<uint32_t>(flags.data, swap) >> 11) & 1;
  const Element dims = next_element(r);
  if (dims.type != miINT32 || dims.bytes < 8 || dims.bytes % 4 || dims.bytes > 4 * 32) r.fail("dimensions (2 to 32 of them)");
  MatArray a;
  int64_t count = 1;
  for (size_t i = 0; i < dims.bytes / 4; ++i) {
    const int32_t d = load<int32_t>(dims.data + 4 * i, swap);
    if (d < 0) r.fail("negative dimension");
    a.dims.push_back(d);
    if (d > 0 && count > kMaxElements / d) r.fail("more than 2^27 elements");  // checked before it can overflow
    count *= d;
  }
  const Element name = next_element(r);
  if (name.type != miINT8) r.fail("array name");
  const std::string var(reinterpret_cast<const char*>(name.data), name.bytes);
  const bool numeric = cls >= mxDOUBLE && cls <= mxUINT64;
  if ((!numeric && cls != mxCHAR) || complex) {
    out.skipped.push_back(var);
    return;
  }
  const Element real = next_element(r);
  const size_t es = type_size(real.type);
  if (es == 0) r.fail("variable " + var + " has data of type " + std::to_string(real.type));
  if (real.bytes != size_t(count) * es)
    r.fail("variable " + var + " holds " + std::to_string(real.bytes / es) + " values for " + std::to_string(count) + " elements");
  a.values.resize(size_t(count));
  for (int64_t i = 0; i < count; ++i) a.values[size_t(i)] = element_value(real.type, real.data + size_t(i) * es, swap);
  if (cls == mxCHAR) {
    a.is_char = true;
    for (double v : a.values) a.text.push_back(v >= 0 && v < 256 ? char(int(v)) : '?');
    a.values.clear();
  }
  out.arrays[var] = std::move(a);
}

}  // namespace

torch::Tensor MatArray::tensor() const {
  if (is_char) throw InputError("a MAT character array is not numeric");
  // Column-major dims (d0, d1, ..., dk) = row-major (dk, ..., d0), then reverse the axes.
  std::vector<int64_t> rev(dims.rbegin(), dims.rend());
  torch::Tensor t = torch::tensor(values, torch::kFloat64).view(rev);
  std::vector<int64_t> perm;
  for (int64_t i = int64_t(dims.size()) - 1; i >= 0; --i) perm.push_back(i);
  return t.permute(perm).contiguous();
}

const MatArray& MatFile::at(const std::string& name) const {
  auto it = arrays.find(name);
  if (it == arrays.end()) input_error(path, "has no numeric variable '" + name + "'");
  return it->second;
}

MatFile read_mat_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) input_error(path, "cannot be opened");
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.size() < 128) input_error(path, "is not a MAT-file (shorter than its 128-byte header)");
  if (std::memcmp(bytes.data(), "MATLAB 5.0 MAT-file", 19) != 0)
    input_error(path, "is not a MATLAB 5 MAT-file (v7.3 files are HDF5: save with -v7 instead)");
  bool swap;
  if (bytes[126] == 'I' && bytes[127] == 'M') swap = false;
  else if (bytes[126] == 'M' && bytes[127] == 'I') swap = true;
  else input_error(path, "malformed MAT-file: no endian indicator");
  MatFile out;
  out.path = path;
  Reader r{bytes.data(), bytes.size(), 128, swap, path};
  while (r.left() >= 8) {
    const Element e = next_element(r);
    if (e.type == miCOMPRESSED) {
      const std::vector<uint8_t> inner = inflate_all(e, path);
      Reader ri{inner.data(), inner.size(), 0, swap, path};
      while (ri.left() >= 8) {
        const Element m = next_element(ri);
        if (m.type == miMATRIX) read_matrix(m, swap, path, out);
      }
    } else if (e.type == miMATRIX) {
      read_matrix(e, swap, path, out);
    }
  }
  return out;
}

}  // namespace hsd::data
