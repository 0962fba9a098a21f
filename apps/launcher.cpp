// The apps' front door. build/bin/hsd_X is this small program, which loads
// no LibTorch: it answers a lone --help at once (hsd_X's usage, the same
// text as the app's), and otherwise starts the app itself, build/libexec/hsd_X,
// with OMP_WAIT_POLICY=PASSIVE in its environment unless the caller set one
// (LibTorch's OpenMP threads then sleep between parallel regions instead of
// spinning against OpenBLAS's threads on the same cores; common/app.h). The
// app would otherwise set it and re-execute itself: a second load of
// LibTorch and its ~280 libraries, ~0.4 s on every run.
//
// The training apps (hsd_train, hsd_ablate, hsd_bench train) also get
// OPENBLAS_THREAD_TIMEOUT=4 unless the caller set one. OpenBLAS's idle worker
// polls for its next matrix product with sched_yield for 2^28 cycles (~0.1 s,
// the default 28) after every product; in a training step, where the network's
// elementwise work runs between products, that polling holds one of the two
// cores in system calls. With 4 (16 cycles) the worker sleeps at once. Measured
// on an AVX-512 EPYC guest, paired 200-step quick trainings: 0.33-0.35 s per
// step against 0.40-0.41 s, system time 10-11 s against 47 s, the same losses.
// The simulation's back-to-back products are faster with the polling
// (hsd_bench sim, seven layers: 0.65-0.81 s against 0.75-0.90 s), so the
// other apps keep it (docs/benchmarks.md, "OpenBLAS's idle polling").
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include HSD_USAGE_HEADER

namespace {

bool trains(int argc, char** argv) {
  const std::string app = HSD_APP_NAME;
  return app == "hsd_train" || app == "hsd_ablate" || (app == "hsd_bench" && argc > 1 && std::strcmp(argv[1], "train") == 0);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 2 && std::strcmp(argv[1], "--help") == 0) {
    std::printf("%s\n", hsd::usage::kText);
    return 0;
  }
  char self[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", self, sizeof self - 1);
  if (n <= 0) {
    std::fprintf(stderr, "%s: error: cannot find this program's folder (/proc/self/exe): %s\n", HSD_APP_NAME, std::strerror(errno));
    return 1;
  }
  self[n] = '\0';
  std::string dir(self);
  dir.erase(dir.find_last_of('/'));
  const std::string app = dir + "/../libexec/" HSD_APP_NAME;
  if (std::getenv("OMP_WAIT_POLICY") == nullptr) ::setenv("OMP_WAIT_POLICY", "PASSIVE", 1);
  if (trains(argc, argv) && std::getenv("OPENBLAS_THREAD_TIMEOUT") == nullptr) ::setenv("OPENBLAS_THREAD_TIMEOUT", "4", 1);
  argv[0] = const_cast<char*>(HSD_APP_NAME);
  ::execv(app.c_str(), argv);
  std::fprintf(stderr, "%s: error: cannot start %s: %s (build the project: cmake --build build)\n", HSD_APP_NAME,
               app.c_str(), std::strerror(errno));
  return 1;
}
