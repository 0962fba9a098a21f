#include "common/log.h"

#include <atomic>
#include <cstdio>
#include <unistd.h>

namespace hsd::log {
namespace {
std::atomic<int> g_warnings{0};
std::atomic<bool> g_quiet{false};
}  // namespace

void info(const std::string& msg) {
  if (!g_quiet) std::fprintf(stderr, "%s\n", msg.c_str());
}
void warn(const std::string& msg) {
  ++g_warnings;
  std::fprintf(stderr, "warning: %s\n", msg.c_str());
}
int warning_count() { return g_warnings; }
void set_quiet(bool quiet) { g_quiet = quiet; }

Progress::Progress(std::string label, long total)
    : label_(std::move(label)), total_(total > 0 ? total : 1), tty_(isatty(fileno(stderr)) != 0),
      start_(std::chrono::steady_clock::now()), last_(start_) {}

void Progress::step(long n) {
  done_ += n;
  if (done_ >= total_) return;  // the end: finish() prints
  auto now = std::chrono::steady_clock::now();
  if (tty_) {  // a live bar, redrawn at most every 0.5 s
    if (std::chrono::duration<double>(now - last_).count() < 0.5) return;
  } else {  // a log file: one line each time another kNonTtyPercent % is done
    const long bucket = long(100.0 * double(done_) / double(total_)) / kNonTtyPercent;
    if (bucket <= last_bucket_) return;
    last_bucket_ = bucket;
  }
  last_ = now;
  print(false);
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  print(true);
}

Progress::~Progress() { finish(); }

void Progress::print(bool final_line) {
  if (g_quiet) return;
  const int width = 30;
  const double frac = std::min(1.0, double(done_) / double(total_));
  const int filled = int(frac * width + 0.5);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  std::string bar(filled, '#');
  bar += std::string(width - filled, '.');
  const bool tty = tty_;
  std::string eta;
  if (!final_line && done_ > start_done_ && done_ < total_) {
    char buf[48];
    std::snprintf(buf, sizeof buf, "  ETA %.0f s", secs / double(done_ - start_done_) * double(total_ - done_));
    eta = buf;
  }
  std::fprintf(stderr, "%s%s [%s] %ld/%ld  %.1f s%s%s%s%s", tty ? "\r" : "", label_.c_str(), bar.c_str(), done_,
               total_, secs, suffix_.empty() ? "" : "  ", suffix_.c_str(), eta.c_str(),
               (final_line || !tty) ? "\n" : (tty ? "\033[K" : ""));
  std::fflush(stderr);
}

}  // namespace hsd::log
