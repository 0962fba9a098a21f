#include "common/subprocess.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <cerrno>

extern char** environ;

namespace hsd {

std::string ProcessEnd::describe() const {
  if (!started) return "could not be started";
  if (signal != 0) return "signal " + std::to_string(signal);
  return "exit status " + std::to_string(exit_code);
}

ProcessEnd run_process(const std::vector<std::string>& argv, bool quiet) {
  ProcessEnd end;
  if (argv.empty()) return end;
  std::vector<char*> cargv;
  for (const auto& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  if (quiet) {
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
  }
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, cargv[0], &fa, nullptr, cargv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) return end;
  end.started = true;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return end;  // lost: exit_code stays -1
  if (WIFEXITED(status)) end.exit_code = WEXITSTATUS(status);
  else if (WIFSIGNALED(status)) end.signal = WTERMSIG(status);
  return end;
}

}  // namespace hsd
