#include "io/input_text.h"

namespace lfrecon {
namespace {

std::string Printable(const std::string& text, std::size_t n) {
  std::string out;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    out += c >= 0x20 && c < 0x7f ? text[i] : '?';
  }
  return out;
}

}  // namespace

std::string InputToken(const std::string& text) {
  if (text.size() > kMaxInputTokenChars) return "a text of " + std::to_string(text.size()) + " bytes";
  return "'" + Printable(text, text.size()) + "'";
}

std::string PeerText(const std::string& text, std::size_t max_chars) {
  if (text.size() <= max_chars) return Printable(text, text.size());
  return Printable(text, max_chars) + "... (" + std::to_string(text.size()) + " bytes)";
}

}  // namespace lfrecon
