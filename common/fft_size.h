// FFT sizes: the smallest 2^a 3^b 5^c at least n. Convolutions by FFT need a
// size >= H + 2r; sizes with a large prime factor, such as 318 = 2·3·53 for a
// 256 patch and a 63-pixel PSF, are several times slower.
#pragma once
#include <cstdint>

namespace hsd {

int64_t fast_fft_size(int64_t n);

}  // namespace hsd
