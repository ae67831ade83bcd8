#include "io/file_bytes.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "common/test_util.h"
#include "util/error.h"

namespace lfrecon {
namespace {

namespace fs = std::filesystem;

fs::path WriteFile(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return p;
}

TEST(ReadFileBytes, ReturnsEveryByteOfABinaryFile) {
  std::string bytes;
  for (int i = 0; i < 3 * 1000 * 1000 + 7; ++i) bytes.push_back(static_cast<char>((i * 131) % 256));  // zeros too
  const testing::TempDir dir;
  EXPECT_EQ(ReadFileBytes(WriteFile(dir.path() / "binary", bytes)), bytes);
  EXPECT_EQ(ReadFileBytes(WriteFile(dir.path() / "empty", "")), "");
}

TEST(ReadFileBytes, RefusesAFileOverTheLimitNamingIt) {
  const testing::TempDir dir;
  const fs::path p = WriteFile(dir.path() / "large", std::string(5000, 'x'));
  EXPECT_EQ(ReadFileBytes(p, 5000).size(), 5000u);
  try {
    ReadFileBytes(p, 4999);
    FAIL() << "a file over the limit was read";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), p.string());
    EXPECT_NE(std::string(e.what()).find("larger than 4999 bytes"), std::string::npos) << e.what();
  }
}

TEST(ReadFileBytes, ReadsFilesWhoseSizeIsUnknown) {
  // /proc's files report size 0 but have content.
  const std::string status = ReadFileBytes("/proc/self/status");
  EXPECT_NE(status.find("Name:"), std::string::npos);
  EXPECT_THROW(ReadFileBytes("/proc/self/status", 10), InputError);
}

TEST(ReadFileBytes, NamesAMissingFile) {
  const testing::TempDir dir;
  const fs::path p = dir.path() / "no_such_file";
  try {
    ReadFileBytes(p);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), p.string());
  }
}

}  // namespace
}  // namespace lfrecon
