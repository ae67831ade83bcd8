#include "io/file_bytes.h"

#include <fstream>

#include "util/error.h"

namespace lfrecon {

namespace {

// "2 GiB" for 2^31 and for 2^31 - 1 (the limit of an int count), else bytes.
std::string LimitText(std::uintmax_t max_bytes) {
  for (const std::uintmax_t m : {max_bytes, max_bytes + 1}) {
    if (m >= (std::uintmax_t{1} << 30) && m % (std::uintmax_t{1} << 30) == 0) return std::to_string(m >> 30) + " GiB";
    if (m >= (std::uintmax_t{1} << 20) && m % (std::uintmax_t{1} << 20) == 0) return std::to_string(m >> 20) + " MiB";
  }
  return std::to_string(max_bytes) + " bytes";
}

}  // namespace

std::string ReadFileBytes(const std::filesystem::path& path, std::uintmax_t max_bytes) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(file, "cannot open file");
  auto too_large = [&] { return InputError(file, "file larger than " + LimitText(max_bytes)); };
  std::error_code ec;
  std::string bytes;
  if (std::filesystem::is_regular_file(path, ec)) {
    const std::uintmax_t size = std::filesystem::file_size(path, ec);
    if (!ec && size > 0) {  // /proc's files say 0 and are read in blocks
      if (size > max_bytes) throw too_large();
      bytes.resize(static_cast<std::size_t>(size));
      in.read(bytes.data(), static_cast<std::streamsize>(size));
      if (in.bad() || static_cast<std::uintmax_t>(in.gcount()) != size)
        throw InputError(file, "read failed (the file changed or could not be read)");
      return bytes;
    }
  }
  // Size unknown: blocks of 1 MiB until the end or the limit.
  constexpr std::size_t kBlock = std::size_t{1} << 20;
  while (in) {
    const std::size_t at = bytes.size();
    bytes.resize(at + kBlock);
    in.read(bytes.data() + at, static_cast<std::streamsize>(kBlock));
    bytes.resize(at + static_cast<std::size_t>(in.gcount()));
    if (bytes.size() > max_bytes) throw too_large();
  }
  if (in.bad()) throw InputError(file, "read failed");
  return bytes;
}

}  // namespace lfrecon
