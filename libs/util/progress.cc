#include "util/progress.h"

#include <spdlog/spdlog.h>

#include <ctime>

namespace lfrecon {

double ProcessCpuSeconds() {
  timespec ts{};
  if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) != 0) return 0.0;
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

Progress::Progress(std::string task, long long total, double interval_s)
    : task_(std::move(task)), total_(total), interval_s_(interval_s) {
  start_ = last_ = std::chrono::steady_clock::now();
}

Progress::~Progress() { Finish(); }

void Progress::Advance(long long n) {
  done_ += n;
  const auto now = std::chrono::steady_clock::now();
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || finished_) return;
  if (std::chrono::duration<double>(now - last_).count() >= interval_s_) {
    last_ = now;
    Log(false);
  }
}

void Progress::Finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  finished_ = true;
  Log(true);
}

void Progress::Log(bool final_line) {
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const long long done = done_.load();
  const double rate = elapsed > 0 ? done / elapsed : 0.0;
  if (total_ > 0) {
    const double pct = 100.0 * done / total_;
    const double eta = rate > 0 ? (total_ - done) / rate : 0.0;
    if (final_line)
      spdlog::info("{}: {}/{} done in {:.1f} s ({:.2f}/s)", task_, done, total_, elapsed, rate);
    else
      spdlog::info("{}: {}/{} ({:.0f}%) {:.2f}/s, eta {:.0f} s", task_, done, total_, pct, rate, eta);
  } else {
    spdlog::info("{}: {} done in {:.1f} s ({:.2f}/s)", task_, done, elapsed, rate);
  }
}

}  // namespace lfrecon
