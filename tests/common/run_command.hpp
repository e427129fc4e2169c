#pragma once
/// Running a command from a test (header only): the CLI tests and the cross-checks against
/// independent decoders.

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "tests/common/test_files.hpp"

namespace pumptherm::test_files {

struct CommandResult {
  int exit_code = -1;  ///< the exit status; -1 when it could not start or did not exit normally
  std::string out;     ///< what it wrote (RunCommand: stdout; RunCommandStderr: stderr)
};

inline int ExitCode(int status) {
  return status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/// Runs `command` with /bin/sh and collects its stdout.
inline CommandResult RunCommand(const std::string& command) {
  CommandResult r;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return r;
  char buf[65536];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) r.out.append(buf, n);
  r.exit_code = ExitCode(pclose(pipe));
  return r;
}

/// Runs `command` with /bin/sh, its stderr going to the file `err_path`, and returns that file's
/// text.
inline CommandResult RunCommandStderr(const std::string& command, const std::string& err_path) {
  CommandResult r;
  r.exit_code = ExitCode(std::system((command + " 2> '" + err_path + "'").c_str()));
  r.out = ReadFile(err_path);
  return r;
}

}  // namespace pumptherm::test_files
