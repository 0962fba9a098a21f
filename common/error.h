// Errors with a meaning for the user.
//   InputError     : the user's input (config key, flag, file) is wrong -> exit code 2,
//                    one line that names the key path or file and the reason.
//   NumericalError : a NaN/Inf or an impossible value appeared inside a computation
//                    -> exit code 3, naming where it was detected.
//   DistributedError: data-parallel training lost a peer (a rank died, stalled
//                    past the timeout or could not be reached) -> exit code 4,
//                    naming this rank and the collective that failed.
// Anything else that escapes an app is a bug -> exit code 1.
#pragma once
#include <stdexcept>
#include <string>

namespace at { class Tensor; }

namespace hsd {

struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct NumericalError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct DistributedError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Throws InputError("<where>: <what>").
[[noreturn]] void input_error(const std::string& where, const std::string& what);

// Throws NumericalError naming `where` if `t` holds a NaN or an Inf. Cheap enough
// for per-step checks (one reduction); no-op for non-floating tensors.
void check_finite(const at::Tensor& t, const std::string& where);

// "" if t is all finite, else where the first NaN/Inf sits (row-major), e.g.
// "NaN at [0, 2, 5, 7] (3 of 1200 values)"; for images [C, H, W] read as
// channel, row, column.
std::string first_nonfinite(const at::Tensor& t);

// For data a user gave: InputError "<file>: <what> holds NaN at [...]" (exit 2).
void check_finite_input(const at::Tensor& t, const std::string& file, const std::string& what);

}  // namespace hsd
