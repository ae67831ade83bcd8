#pragma once
// Runs an external program as a child process from an argv array (posix_spawn,
// no shell), streams its stdout/stderr line by line to a callback and keeps the
// last lines of its output for error messages.
#include <deque>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace lfrecon {

// An external tool that is missing or failed; the message names the binary.
class ExternalToolError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct SubprocessResult {
  int exit_status = 0;                  // exit code, or 128 + signal number when killed by a signal
  bool signaled = false;
  std::deque<std::string> last_lines;   // the last output lines (stdout and stderr interleaved as read)
  double seconds = 0;
};

struct SubprocessOptions {
  std::filesystem::path working_dir;  // empty: the current one
  std::size_t keep_lines = 20;        // lines kept in SubprocessResult::last_lines
  // Called for every output line (stderr = true for the child's stderr).
  std::function<void(const std::string& line, bool stderr)> on_line;
};

// The absolute path of `program` (as given when it has a '/', else looked up in
// PATH); empty if it is not an executable file.
std::filesystem::path FindExecutable(const std::string& program);

// Runs argv[0] with argv (argv[0] looked up in PATH when it has no '/').
// Throws ExternalToolError naming argv[0] when it cannot be started; returns
// the exit status otherwise (the caller decides what a failure means).
SubprocessResult RunSubprocess(const std::vector<std::string>& argv, const SubprocessOptions& options = {});

}  // namespace lfrecon
