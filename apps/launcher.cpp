// The apps' front door. build/bin/hsd_X is this small program, which loads
// no LibTorch: it answers a lone --help at once (hsd_X's usage, the same
// text as the app's), and otherwise starts the app itself, build/libexec/hsd_X,
// with OMP_WAIT_POLICY=PASSIVE in its environment unless the caller set one
// (LibTorch's OpenMP threads then sleep between parallel regions instead of
// spinning against OpenBLAS's threads on the same cores; common/app.h). The
// app would otherwise set it and re-execute itself: a second load of
// LibTorch and its ~280 libraries, ~0.4 s on every run.
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include HSD_USAGE_HEADER

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
  argv[0] = const_cast<char*>(HSD_APP_NAME);
  ::execv(app.c_str(), argv);
  std::fprintf(stderr, "%s: error: cannot start %s: %s (build the project: cmake --build build)\n", HSD_APP_NAME,
               app.c_str(), std::strerror(errno));
  return 1;
}
