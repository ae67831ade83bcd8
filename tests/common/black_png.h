#pragma once
// A valid PNG of `width` x `height` 1-bit grey pixels, all black: deflate makes
// it small however large it is (20000x20000: 50 MB of rows, a 49 KB file), so
// tests can hand readers huge images without huge files. Link ZLIB::ZLIB.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdint>
#include <string>

namespace lfrecon::testing {

inline std::string BlackPng(std::uint32_t width, std::uint32_t height) {
  auto be32 = [](std::uint32_t v) {
    return std::string{static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8),
                       static_cast<char>(v)};
  };
  auto chunk = [&](const std::string& type, const std::string& data) {
    const std::string body = type + data;
    const auto crc = static_cast<std::uint32_t>(
        ::crc32(0, reinterpret_cast<const Bytef*>(body.data()), static_cast<uInt>(body.size())));
    return be32(static_cast<std::uint32_t>(data.size())) + body + be32(crc);
  };
  const std::string ihdr = be32(width) + be32(height) + std::string("\x01\x00\x00\x00\x00", 5);  // 1 bit, grey
  const std::string rows(static_cast<std::size_t>(height) * (1 + (width + 7) / 8), '\0');  // filter 0, zeros
  uLongf size = ::compressBound(rows.size());
  std::string z(size, '\0');
  EXPECT_EQ(::compress2(reinterpret_cast<Bytef*>(z.data()), &size, reinterpret_cast<const Bytef*>(rows.data()),
                        rows.size(), 1),
            Z_OK);
  z.resize(size);
  return std::string("\x89PNG\r\n\x1a\n", 8) + chunk("IHDR", ihdr) + chunk("IDAT", z) + chunk("IEND", "");
}

}  // namespace lfrecon::testing
