#include "sfm/subprocess.h"

#include <fcntl.h>
#include <poll.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>

extern char** environ;

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

bool IsExecutableFile(const fs::path& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode) && ::access(p.c_str(), X_OK) == 0;
}

// Splits what arrives on one pipe into lines.
struct LineBuffer {
  std::string pending;
  bool is_stderr = false;
};

void Emit(const std::string& line, bool is_stderr, const SubprocessOptions& options, SubprocessResult* result) {
  std::string l = line;
  if (!l.empty() && l.back() == '\r') l.pop_back();
  // Progress bars rewrite one line with '\r': keep the last state.
  const std::size_t cr = l.rfind('\r');
  if (cr != std::string::npos) l = l.substr(cr + 1);
  if (options.on_line) options.on_line(l, is_stderr);
  if (options.keep_lines > 0) {
    result->last_lines.push_back(l);
    while (result->last_lines.size() > options.keep_lines) result->last_lines.pop_front();
  }
}

}  // namespace

fs::path FindExecutable(const std::string& program) {
  if (program.empty()) return {};
  if (program.find('/') != std::string::npos) {
    return IsExecutableFile(program) ? fs::absolute(program) : fs::path();
  }
  const char* path_env = std::getenv("PATH");
  const std::string path = path_env ? path_env : "/usr/local/bin:/usr/bin:/bin";
  std::size_t start = 0;
  while (start <= path.size()) {
    const std::size_t end = std::min(path.find(':', start), path.size());
    const std::string dir = path.substr(start, end - start);
    const fs::path candidate = fs::path(dir.empty() ? "." : dir) / program;
    if (IsExecutableFile(candidate)) return fs::absolute(candidate);
    start = end + 1;
  }
  return {};
}

SubprocessResult RunSubprocess(const std::vector<std::string>& argv, const SubprocessOptions& options) {
  if (argv.empty()) throw std::invalid_argument("RunSubprocess: empty argv");
  const fs::path exe = FindExecutable(argv[0]);
  if (exe.empty()) {
    throw ExternalToolError("'" + argv[0] + "' not found" +
                            (argv[0].find('/') == std::string::npos ? " on PATH" : "") +
                            " (or not an executable file)");
  }
  int out_pipe[2], err_pipe[2];
  if (::pipe2(out_pipe, O_CLOEXEC) != 0) throw ExternalToolError(argv[0] + ": pipe: " + std::strerror(errno));
  if (::pipe2(err_pipe, O_CLOEXEC) != 0) {
    ::close(out_pipe[0]);
    ::close(out_pipe[1]);
    throw ExternalToolError(argv[0] + ": pipe: " + std::strerror(errno));
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&actions, out_pipe[1], 1);
  posix_spawn_file_actions_adddup2(&actions, err_pipe[1], 2);
  std::string cwd_for_child;
  if (!options.working_dir.empty()) {
    cwd_for_child = options.working_dir.string();
#if defined(__GLIBC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 29))
    posix_spawn_file_actions_addchdir_np(&actions, cwd_for_child.c_str());
#else
#error "posix_spawn_file_actions_addchdir_np needs glibc >= 2.29"
#endif
  }
  std::vector<char*> args;
  args.reserve(argv.size() + 1);
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);

  const auto start = std::chrono::steady_clock::now();
  pid_t pid = 0;
  const int rc = ::posix_spawn(&pid, exe.c_str(), &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  ::close(out_pipe[1]);
  ::close(err_pipe[1]);
  if (rc != 0) {
    ::close(out_pipe[0]);
    ::close(err_pipe[0]);
    throw ExternalToolError("cannot start '" + exe.string() + "': " + std::strerror(rc));
  }

  SubprocessResult result;
  LineBuffer buffers[2];
  buffers[1].is_stderr = true;
  pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
  int open_fds = 2;
  char chunk[8192];
  while (open_fds > 0) {
    const int n = ::poll(fds, 2, -1);
    if (n < 0) {
      if (errno == EINTR) continue;
      break;
    }
    for (int k = 0; k < 2; ++k) {
      if (fds[k].fd < 0 || (fds[k].revents & (POLLIN | POLLHUP | POLLERR)) == 0) continue;
      const ssize_t got = ::read(fds[k].fd, chunk, sizeof(chunk));
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) {
        if (!buffers[k].pending.empty()) Emit(buffers[k].pending, buffers[k].is_stderr, options, &result);
        buffers[k].pending.clear();
        ::close(fds[k].fd);
        fds[k].fd = -1;
        --open_fds;
        continue;
      }
      std::string& p = buffers[k].pending;
      p.append(chunk, static_cast<std::size_t>(got));
      std::size_t nl;
      while ((nl = p.find('\n')) != std::string::npos) {
        Emit(p.substr(0, nl), buffers[k].is_stderr, options, &result);
        p.erase(0, nl + 1);
      }
    }
  }
  for (auto& f : fds)
    if (f.fd >= 0) ::close(f.fd);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status)) {
    result.exit_status = WEXITSTATUS(status);
  } else if (WIFSIGNALED(status)) {
    result.signaled = true;
    result.exit_status = 128 + WTERMSIG(status);
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace lfrecon
