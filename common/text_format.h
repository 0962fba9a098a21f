// Numbers into text for logs, reports and tables: printf-style formatting into
// a std::string (the format checked by the compiler), and a number to a given
// count of significant digits.
#pragma once
#include <string>

namespace hsd {

// printf-style: format("%.2f dB", psnr).
std::string format(const char* f, ...) __attribute__((format(printf, 1, 2)));

// v with `digits` significant digits, as %.*g: format_g(0.123456) == "0.1235".
std::string format_g(double v, int digits = 4);

}  // namespace hsd
