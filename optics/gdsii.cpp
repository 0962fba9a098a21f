#include "optics/gdsii.h"

#include <cmath>
#include <stdexcept>

namespace hsd::optics {

namespace {

class RecordWriter {
 public:
  void record(uint16_t type, const std::vector<unsigned char>& payload) {
    const size_t len = 4 + payload.size();
    if (len > 65534) throw std::invalid_argument("GDSII record too long");
    put16(uint16_t(len));
    put16(type);
    bytes_.insert(bytes_.end(), payload.begin(), payload.end());
  }
  void empty(uint16_t type) { record(type, {}); }
  void int16s(uint16_t type, const std::vector<int64_t>& v) {
    std::vector<unsigned char> p;
    for (int64_t x : v) {
      const uint16_t u = uint16_t(int16_t(x));
      p.push_back(u >> 8), p.push_back(u & 0xff);
    }
    record(type, p);
  }
  void int32s(uint16_t type, const std::vector<int64_t>& v) {
    std::vector<unsigned char> p;
    for (int64_t x : v) {
      const uint32_t u = uint32_t(int32_t(x));
      for (int s = 24; s >= 0; s -= 8) p.push_back((u >> s) & 0xff);
    }
    record(type, p);
  }
  void reals(uint16_t type, const std::vector<double>& v) {
    std::vector<unsigned char> p;
    for (double x : v) {
      unsigned char b[8];
      gdsii_real8(x, b);
      p.insert(p.end(), b, b + 8);
    }
    record(type, p);
  }
  void text(uint16_t type, const std::string& s) {
    std::vector<unsigned char> p(s.begin(), s.end());
    if (p.size() % 2) p.push_back(0);  // records have even length
    record(type, p);
  }
  std::vector<char> take() { return std::vector<char>(bytes_.begin(), bytes_.end()); }

 private:
  void put16(uint16_t v) { bytes_.push_back(v >> 8), bytes_.push_back(v & 0xff); }
  std::vector<unsigned char> bytes_;
};

// Record types (type << 8 | data type).
constexpr uint16_t HEADER = 0x0002, BGNLIB = 0x0102, LIBNAME = 0x0206, UNITS = 0x0305, ENDLIB = 0x0400,
                   BGNSTR = 0x0502, STRNAME = 0x0606, ENDSTR = 0x0700, BOUNDARY = 0x0800, LAYER = 0x0D02,
                   DATATYPE = 0x0E02, XY = 0x1003, ENDEL = 0x1100;

}  // namespace

void gdsii_real8(double v, unsigned char out[8]) {
  for (int i = 0; i < 8; ++i) out[i] = 0;
  if (v == 0.0 || !std::isfinite(v)) return;
  const bool neg = v < 0;
  double m = std::fabs(v);
  int e = 64;
  while (m >= 1.0) m /= 16.0, ++e;
  while (m < 1.0 / 16.0) m *= 16.0, --e;
  // 56-bit mantissa, m in [1/16, 1).
  uint64_t mant = uint64_t(std::llround(std::ldexp(m, 56)));
  if (mant >> 56) {  // rounded up to 1.0
    mant >>= 4;
    ++e;
  }
  out[0] = (unsigned char)((neg ? 0x80 : 0) | (e & 0x7f));
  for (int i = 1; i < 8; ++i) out[i] = (unsigned char)((mant >> (8 * (7 - i))) & 0xff);
}

double gdsii_real8_value(const unsigned char in[8]) {
  uint64_t mant = 0;
  for (int i = 1; i < 8; ++i) mant = (mant << 8) | in[i];
  const int e = (in[0] & 0x7f) - 64;
  const double v = std::ldexp(double(mant), -56) * std::pow(16.0, e);
  return (in[0] & 0x80) ? -v : v;
}

std::vector<char> gdsii_bytes(const std::vector<GdsLayer>& layers, int64_t n, double pitch_m, const std::string& cell_name,
                              const std::string& library_name) {
  constexpr double kDbUnitM = 1e-9, kUserUnitM = 1e-6;
  const double pitch_db = pitch_m / kDbUnitM;
  const int64_t p = std::llround(pitch_db);
  if (p <= 0 || std::fabs(pitch_db - double(p)) > 1e-6 * pitch_db)
    throw std::invalid_argument("the DOE pitch " + std::to_string(pitch_m) + " m is not a whole number of nanometres");
  const int64_t half = n * p / 2;  // the grid's centre at the origin (n even: a cell corner; odd: n·p/2 rounded)
  if (n * p > 2'000'000'000LL) throw std::invalid_argument("the DOE is too large for GDSII's 32-bit nm coordinates");
  RecordWriter w;
  const std::vector<int64_t> date{2026, 1, 1, 0, 0, 0};  // fixed: the same masks give the same bytes
  w.int16s(HEADER, {600});
  std::vector<int64_t> dates = date;
  dates.insert(dates.end(), date.begin(), date.end());
  w.int16s(BGNLIB, dates);
  w.text(LIBNAME, library_name);
  w.reals(UNITS, {kDbUnitM / kUserUnitM, kDbUnitM});
  w.int16s(BGNSTR, dates);
  w.text(STRNAME, cell_name);
  for (const GdsLayer& l : layers) {
    for (const CellRect& r : l.rects) {
      const int64_t x0 = r.col0 * p - half, x1 = (r.col0 + r.cols) * p - half;
      const int64_t y0 = r.row0 * p - half, y1 = (r.row0 + r.rows) * p - half;
      w.empty(BOUNDARY);
      w.int16s(LAYER, {l.layer});
      w.int16s(DATATYPE, {0});
      w.int32s(XY, {x0, y0, x1, y0, x1, y1, x0, y1, x0, y0});
      w.empty(ENDEL);
    }
  }
  w.empty(ENDSTR);
  w.empty(ENDLIB);
  return w.take();
}

}  // namespace hsd::optics
