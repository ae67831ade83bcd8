#include "io/input_text.h"

#include <gtest/gtest.h>

#include <string>

namespace lfrecon {
namespace {

TEST(InputToken, QuotesShortPrintableTextAndGivesOnlyTheLengthOfLongText) {
  EXPECT_EQ(InputToken("PINHOLE"), "'PINHOLE'");
  EXPECT_EQ(InputToken(std::string("a\nb\x1b[0m\x00\xff", 9)), "'a?b?[0m??'");
  EXPECT_EQ(InputToken(std::string(32, 'x')), "'" + std::string(32, 'x') + "'");
  EXPECT_EQ(InputToken(std::string(33, 'x')), "a text of 33 bytes");
}

TEST(PeerText, PrintableAsciiCutAtTheBoundWithTheLength) {
  EXPECT_EQ(PeerText("depth@host:42"), "depth@host:42");
  EXPECT_EQ(PeerText(std::string("x\r\n[error] y\x07\x80", 14)), "x??[error] y??");
  EXPECT_EQ(PeerText(std::string(256, 'e')), std::string(256, 'e'));
  const std::string long_text = "\n" + std::string(10239, 'e');
  EXPECT_EQ(PeerText(long_text), "?" + std::string(255, 'e') + "... (10240 bytes)");
  EXPECT_EQ(PeerText("abcdef", 3), "abc... (6 bytes)");
  EXPECT_EQ(PeerText("", 3), "");
}

}  // namespace
}  // namespace lfrecon
