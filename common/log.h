// Console output for apps and long computations: info/warn lines on stderr
// (stdout stays clean for --json results) and a simple progress bar.
#pragma once
#include <chrono>
#include <string>

namespace hsd::log {

void info(const std::string& msg);
void warn(const std::string& msg);
// Number of warnings printed so far (tests use it to check that a warning fired).
int warning_count();
// Silence info lines (warnings always print). Used by hsd_bench --json and tests.
void set_quiet(bool quiet);

// Progress over `total` units of work on stderr: "label [#####.....] 12/25  3.1 s".
// On a terminal, one line redrawn at most every 0.5 s; otherwise (a log file)
// one line per kNonTtyPercent % of the work; and always a line at the end.
constexpr long kNonTtyPercent = 5;
class Progress {
 public:
  Progress(std::string label, long total);
  void step(long n = 1);
  // Extra text after the counts (e.g. "loss 0.031  2.1 step/s"); an ETA is added
  // once some work is done. Start offsets the count (a resumed run).
  void set_suffix(std::string suffix) { suffix_ = std::move(suffix); }
  void set_start(long done) {
    done_ = start_done_ = done;
    last_bucket_ = long(100.0 * double(done) / double(total_)) / kNonTtyPercent;
  }
  void finish();
  ~Progress();

 private:
  void print(bool final_line);
  std::string label_;
  long total_, done_ = 0, start_done_ = 0;
  std::string suffix_;
  bool finished_ = false;
  bool tty_ = false;
  long last_bucket_ = 0;
  std::chrono::steady_clock::time_point start_, last_;
};

}  // namespace hsd::log
