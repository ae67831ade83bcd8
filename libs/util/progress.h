#pragma once
// A progress line for long work: logs "<task>: done/total (pct) rate, eta" at
// most every `interval_s` seconds and once at the end. Thread-safe.
#include <atomic>
#include <chrono>
#include <mutex>
#include <string>

namespace lfrecon {

class Progress {
 public:
  Progress(std::string task, long long total, double interval_s = 2.0);
  ~Progress();

  // Adds `n` finished units; may log.
  void Advance(long long n = 1);
  // Logs the final line (also done by the destructor if not called).
  void Finish();
  long long done() const { return done_.load(); }

 private:
  void Log(bool final_line);

  std::string task_;
  long long total_;
  double interval_s_;
  std::atomic<long long> done_{0};
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_, last_;
  bool finished_ = false;
};

// The process's CPU time so far (user + system, all threads), seconds.
double ProcessCpuSeconds();

// Stopwatch: wall-clock seconds, and the process's CPU seconds (every thread,
// so a parallel stage counts all its cores) since it started.
class Timer {
 public:
  Timer() : start_(std::chrono::steady_clock::now()), cpu_start_(ProcessCpuSeconds()) {}
  void Restart() {
    start_ = std::chrono::steady_clock::now();
    cpu_start_ = ProcessCpuSeconds();
  }
  double Seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  double CpuSeconds() const { return ProcessCpuSeconds() - cpu_start_; }

 private:
  std::chrono::steady_clock::time_point start_;
  double cpu_start_;
};

}  // namespace lfrecon
