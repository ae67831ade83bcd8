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

// Wall-clock stopwatch.
class Timer {
 public:
  Timer() : start_(std::chrono::steady_clock::now()) {}
  void Restart() { start_ = std::chrono::steady_clock::now(); }
  double Seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace lfrecon
