#include "io/file_bytes.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "util/error.h"

namespace lfrecon {
namespace {

namespace fs = std::filesystem;

fs::path TempFile(const std::string& name, const std::string& bytes) {
  const fs::path p = fs::temp_directory_path() / ("lfrecon_file_bytes_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(p, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return p;
}

TEST(ReadFileBytes, ReturnsEveryByteOfABinaryFile) {
  std::string bytes;
  for (int i = 0; i < 3 * 1000 * 1000 + 7; ++i) bytes.push_back(static_cast<char>((i * 131) % 256));  // zeros too
  const fs::path p = TempFile("binary", bytes);
  EXPECT_EQ(ReadFileBytes(p), bytes);
  EXPECT_EQ(ReadFileBytes(TempFile("empty", "")), "");
  fs::remove(p);
}

TEST(ReadFileBytes, RefusesAFileOverTheLimitNamingIt) {
  const fs::path p = TempFile("large", std::string(5000, 'x'));
  EXPECT_EQ(ReadFileBytes(p, 5000).size(), 5000u);
  try {
    ReadFileBytes(p, 4999);
    FAIL() << "a file over the limit was read";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), p.string());
    EXPECT_NE(std::string(e.what()).find("larger than 4999 bytes"), std::string::npos) << e.what();
  }
  fs::remove(p);
}

TEST(ReadFileBytes, ReadsFilesWhoseSizeIsUnknown) {
  // /proc's files report size 0 but have content.
  const std::string status = ReadFileBytes("/proc/self/status");
  EXPECT_NE(status.find("Name:"), std::string::npos);
  EXPECT_THROW(ReadFileBytes("/proc/self/status", 10), InputError);
}

TEST(ReadFileBytes, NamesAMissingFile) {
  const fs::path p = fs::temp_directory_path() / "lfrecon_file_bytes_no_such_file";
  try {
    ReadFileBytes(p);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), p.string());
  }
}

}  // namespace
}  // namespace lfrecon
