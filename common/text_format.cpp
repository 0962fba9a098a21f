#include "common/text_format.h"

#include <cstdarg>
#include <cstdio>
#include <vector>

namespace hsd {

std::string format(const char* f, ...) {
  va_list args;
  va_start(args, f);
  va_list copy;
  va_copy(copy, args);
  const int n = std::vsnprintf(nullptr, 0, f, copy);
  va_end(copy);
  std::string s;
  if (n > 0) {
    std::vector<char> buf(size_t(n) + 1);
    std::vsnprintf(buf.data(), buf.size(), f, args);
    s.assign(buf.data(), size_t(n));
  }
  va_end(args);
  return s;
}

std::string format_g(double v, int digits) { return format("%.*g", digits, v); }

}  // namespace hsd
