// Child processes without a shell: argv[0] is started with the argument vector
// as given (nothing in a value is interpreted) and this process's environment.
#pragma once
#include <string>
#include <vector>

namespace hsd {

struct ProcessEnd {
  bool started = false;  // false: it could not be started
  int exit_code = -1;    // when it exited
  int signal = 0;        // when a signal ended it
  bool ok() const { return started && signal == 0 && exit_code == 0; }
  // "exit status 2", "signal 9" or "could not be started".
  std::string describe() const;
};

// Runs argv and waits for it. quiet: its stdout and stderr go to /dev/null
// (otherwise they are ours).
ProcessEnd run_process(const std::vector<std::string>& argv, bool quiet = false);

}  // namespace hsd
