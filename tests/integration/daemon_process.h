#pragma once
// Child processes for the integration tests: a daemon killed (SIGKILL) and
// reaped on destruction, and killed by the kernel if the test process dies;
// and a command run to completion with its exit code and output.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace lfrecon::testing {

// `args[0]` is the executable's path; stdout and stderr are appended to `log`.
// `max_file_bytes` > 0: the process's RLIMIT_FSIZE (writes beyond it fail with
// EFBIG; SIGXFSZ is ignored), e.g. a full disk without a mount.
class DaemonProcess {
 public:
  DaemonProcess(const std::vector<std::string>& args, const std::filesystem::path& log, long max_file_bytes = 0)
      : log_(log) {
    pid_ = ::fork();
    if (pid_ == 0) {
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);
      const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      ::dup2(fd, 1);
      ::dup2(fd, 2);
      if (max_file_bytes > 0) {
        ::signal(SIGXFSZ, SIG_IGN);
        const rlimit limit{static_cast<rlim_t>(max_file_bytes), static_cast<rlim_t>(max_file_bytes)};
        ::setrlimit(RLIMIT_FSIZE, &limit);
      }
      std::vector<char*> argv;
      for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
  }
  ~DaemonProcess() { Kill(SIGKILL); }
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;
  void Kill(int sig) {
    if (pid_ <= 0) return;
    ::kill(pid_, sig);
    int status;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
  }
  // SIGTERM; the exit status, or -1 if it had to be killed.
  int Stop() {
    if (pid_ <= 0) return exit_code_;
    ::kill(pid_, SIGTERM);
    for (int i = 0; i < 100; ++i) {
      if (Reaped()) return exit_code_;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    Kill(SIGKILL);
    return -1;
  }
  // Waits up to `timeout` for the process to exit by itself; its exit code (-1
  // if a signal ended it), or -2 if it still runs (it is not killed).
  int WaitExit(std::chrono::milliseconds timeout) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < end) {
      if (pid_ <= 0 || Reaped()) return exit_code_;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -2;
  }
  bool Running() { return pid_ > 0 && !Reaped(); }
  pid_t pid() const { return pid_; }  // -1 once reaped
  const std::filesystem::path& log() const { return log_; }
  std::string Log() const {
    std::ifstream f(log_);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }
  // The last `n` characters of the log.
  std::string LogTail(std::size_t n = 4000) const {
    const std::string s = Log();
    return s.size() > n ? s.substr(s.size() - n) : s;
  }

 private:
  bool Reaped() {
    int status;
    if (::waitpid(pid_, &status, WNOHANG) != pid_) return false;
    pid_ = -1;
    exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return true;
  }
  pid_t pid_ = -1;
  int exit_code_ = -1;
  std::filesystem::path log_;
};

// A TCP port on 127.0.0.1 that was free a moment ago.
inline int FreePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a));
  socklen_t len = sizeof(a);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

struct CommandResult {
  int code = -1;
  std::string output;  // stdout and stderr
};

inline CommandResult RunShell(const std::string& cmd) {
  CommandResult r;
  FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace lfrecon::testing
