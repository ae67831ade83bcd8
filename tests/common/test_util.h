#pragma once
// Helpers shared by the test suites: a per-test temporary folder and an
// assertion that a call throws InputError naming the right things.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
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

// As ExpectInputError, and the message does not echo the file: printable
// ASCII only, at most `max_chars` long, none of the `absent` strings in it.
inline void ExpectInputErrorWithoutEcho(const std::function<void()>& f, const std::vector<std::string>& needles,
                                        const std::vector<std::string>& absent, std::size_t max_chars = 400) {
  try {
    f();
    ADD_FAILURE() << "no InputError thrown";
  } catch (const InputError& e) {
    const std::string what = e.what();
    for (const std::string& n : needles)
      EXPECT_NE(what.find(n), std::string::npos) << "'" << n << "' not in: " << what;
    for (const std::string& a : absent) EXPECT_EQ(what.find(a), std::string::npos) << "echoed: " << what;
    EXPECT_LE(what.size(), max_chars) << what.substr(0, max_chars) << "...";
    const auto bad = std::find_if(what.begin(), what.end(), [](char c) { return c < 0x20 || c >= 0x7f; });
    EXPECT_TRUE(bad == what.end()) << "byte " << static_cast<int>(static_cast<unsigned char>(*bad)) << " at "
                                   << bad - what.begin() << " of: " << what.substr(0, max_chars);
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError, got: " << e.what();
  }
}

}  // namespace lfrecon::testing
