#pragma once
// Helpers shared by the test suites: a per-test temporary folder and an
// assertion that a call throws InputError naming the right things.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "util/error.h"

namespace lfrecon::testing {

// A fresh folder under the system temp dir, named after the running test, mode
// 0700, removed on destruction.
class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::temp_directory_path() /
            ("lfrecon_" + std::string(info->test_suite_name()) + "_" + std::string(info->name()) + "_" +
             std::to_string(::getpid()));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
    // Private (0700): the daemons accept ipc:// sockets without keys only in such folders.
    std::filesystem::permissions(path_, std::filesystem::perms::owner_all);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// `f` must throw InputError whose message contains every needle.
inline void ExpectInputError(const std::function<void()>& f, const std::vector<std::string>& needles) {
  try {
    f();
    ADD_FAILURE() << "no InputError thrown";
  } catch (const InputError& e) {
    for (const std::string& n : needles)
      EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << "'" << n << "' not in: " << e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError, got: " << e.what();
  }
}

}  // namespace lfrecon::testing
