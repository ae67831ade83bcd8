#include "io/input_text.h"

namespace lfrecon {

std::string InputToken(const std::string& text) {
  if (text.size() > kMaxInputTokenChars) return "a text of " + std::to_string(text.size()) + " bytes";
  std::string out = "'";
  for (const char ch : text) {
    const unsigned char c = static_cast<unsigned char>(ch);
    out += c >= 0x20 && c < 0x7f ? ch : '?';
  }
  return out + "'";
}

}  // namespace lfrecon
