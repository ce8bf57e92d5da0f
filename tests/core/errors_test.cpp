// printable_line(): what the CLI makes of every error before printing it.
#include <gtest/gtest.h>

#include <string>

#include "lapflow/core/errors.hpp"

using namespace lapflow;

TEST(PrintableLine, ShortPrintableTextIsUnchanged) {
  EXPECT_EQ(printable_line("dam.0004.ply (frame 4): vertex 1207: velocity is NaN"),
            "dam.0004.ply (frame 4): vertex 1207: velocity is NaN");
  EXPECT_EQ(printable_line(""), "");
  // UTF-8 stays readable: units, accented paths.
  EXPECT_EQ(printable_line("radius 1e-06 m on 2.37 m² of surface (/tmp/été/m.ply)"),
            "radius 1e-06 m on 2.37 m² of surface (/tmp/été/m.ply)");
  // Trailing newlines (a library's message) are dropped.
  EXPECT_EQ(printable_line("cannot read image\n\n"), "cannot read image");
}

TEST(PrintableLine, ControlCharactersAndInvalidUtf8AreEscaped) {
  EXPECT_EQ(printable_line(std::string("a\nb\rc\td\x1b[31me\x7f", 14)), "a\\x0ab\\x0dc\\x09d\\x1b[31me\\x7f");
  EXPECT_EQ(printable_line(std::string("nul\0byte", 8)), "nul\\x00byte");
  // A lone continuation byte, a truncated sequence, an overlong '/', a
  // surrogate, a C1 control: all escaped byte by byte.
  EXPECT_EQ(printable_line("\x80"), "\\x80");
  EXPECT_EQ(printable_line("\xc3"), "\\xc3");
  EXPECT_EQ(printable_line("\xc0\xaf"), "\\xc0\\xaf");
  EXPECT_EQ(printable_line("\xed\xa0\x80"), "\\xed\\xa0\\x80");
  EXPECT_EQ(printable_line("\xc2\x85"), "\\xc2\\x85");
  EXPECT_EQ(printable_line("\xff\xfe"), "\\xff\\xfe");
  // Four-byte UTF-8 is kept.
  EXPECT_EQ(printable_line("\xf0\x9f\x8c\x8a"), "\xf0\x9f\x8c\x8a");
}

TEST(PrintableLine, LongTextIsCutWithItsLength) {
  const std::string five_mb = "m.obj (frame 1): line 2: " + std::string(5'000'000, '7');
  const std::string line = printable_line(five_mb);
  EXPECT_LE(line.size(), kMaxMessageChars);
  EXPECT_GT(line.size(), kMaxMessageChars - 30) << "the cut keeps as much as fits";
  EXPECT_EQ(line.rfind("m.obj (frame 1): line 2: 777", 0), 0u) << line;
  const std::string tail = "... (" + std::to_string(five_mb.size()) + " characters)";
  EXPECT_EQ(line.substr(line.size() - tail.size()), tail) << line;
  // Exactly the limit: not cut.
  EXPECT_EQ(printable_line(std::string(kMaxMessageChars, 'a')), std::string(kMaxMessageChars, 'a'));
  EXPECT_NE(printable_line(std::string(kMaxMessageChars + 1, 'a')).find("... (301 characters)"), std::string::npos);
  // Raw bytes: escaped, never cut inside an escape or a UTF-8 character.
  std::string raw;
  for (int i = 0; i < 100000; ++i) raw += char(i % 256);
  const std::string escaped = printable_line(raw);
  EXPECT_LE(escaped.size(), kMaxMessageChars);
  const std::string body = escaped.substr(0, escaped.find("... ("));
  for (unsigned char c : body) EXPECT_TRUE(c >= 0x20 && c < 0x7f) << int(c);
  const std::size_t last_escape = body.rfind("\\x");
  ASSERT_NE(last_escape, std::string::npos);
  EXPECT_EQ(body.size() - last_escape >= 4, true) << body;
  // At the cut (300 - 20 characters of tail = 280 bytes kept at most) a
  // two-byte character or a four-byte escape that would straddle it goes.
  EXPECT_EQ(printable_line(std::string(279, 'a') + "é" + std::string(100, 'a')),
            std::string(279, 'a') + "... (381 characters)");
  EXPECT_EQ(printable_line(std::string(279, 'a') + "\x01" + std::string(100, 'a')),
            std::string(279, 'a') + "... (380 characters)");
  EXPECT_EQ(printable_line(std::string(278, 'a') + "é" + std::string(100, 'a')),
            std::string(278, 'a') + "é... (380 characters)");
}
