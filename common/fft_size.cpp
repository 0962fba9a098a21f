#include "common/fft_size.h"

#include <algorithm>

namespace hsd {

int64_t fast_fft_size(int64_t n) {
  for (int64_t m = std::max<int64_t>(n, 1);; ++m) {
    int64_t k = m;
    for (int64_t p : {2, 3, 5})
      while (k % p == 0) k /= p;
    if (k == 1) return m;
  }
}

}  // namespace hsd
