// printable_line(): what the CLI makes of every error before printing it.
#include <gtest/gtest.h>

#include <fmt/format.h>

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

TEST(PrintableLine, LongTextLosesItsMiddleAndKeepsItsEnd) {
  const std::string five_mb = "m.obj (frame 1): line 2: " + std::string(5'000'000, '7') + " is not a number";
  const std::string line = printable_line(five_mb);
  EXPECT_LE(line.size(), kMaxMessageChars);
  EXPECT_GT(line.size(), kMaxMessageChars - 30) << "the cut keeps as much as fits";
  EXPECT_EQ(line.rfind("m.obj (frame 1): line 2: 777", 0), 0u) << line;
  const std::string marker = " ... (" + std::to_string(five_mb.size()) + " characters) ... ";
  EXPECT_NE(line.find(marker), std::string::npos) << line;
  EXPECT_TRUE(line.ends_with("7777 is not a number")) << line;
  // Exactly the limit: not cut.
  EXPECT_EQ(printable_line(std::string(kMaxMessageChars, 'a')), std::string(kMaxMessageChars, 'a'));
  EXPECT_NE(printable_line(std::string(kMaxMessageChars + 1, 'a')).find("(301 characters)"), std::string::npos);
  // Raw bytes: escaped, never cut inside an escape or a UTF-8 character.
  std::string raw;
  for (int i = 0; i < 100000; ++i) raw += char(i % 256);
  const std::string escaped = printable_line(raw);
  EXPECT_LE(escaped.size(), kMaxMessageChars);
  const std::size_t cut = escaped.find(" ... (");
  ASSERT_NE(cut, std::string::npos);
  for (const std::string& part : {escaped.substr(0, cut), escaped.substr(escaped.find(") ... ") + 6)}) {
    for (unsigned char c : part) EXPECT_TRUE(c >= 0x20 && c < 0x7f) << int(c);
  }
  // The cut falls between whole escapes: the end is the escaped end of the bytes.
  std::string end_of_raw;
  for (int i = 100000 - 8; i < 100000; ++i) {
    const unsigned char c = static_cast<unsigned char>(i % 256);
    end_of_raw += c >= 0x20 && c < 0x7f ? std::string(1, char(c)) : fmt::format("\\x{:02x}", c);
  }
  EXPECT_TRUE(escaped.ends_with(end_of_raw)) << escaped;
  // Two-byte characters on both sides of the cut stay whole.
  std::string accents;
  for (int i = 0; i < 400; ++i) accents += "é";
  const std::string cut_accents = printable_line(accents);
  const std::size_t m = cut_accents.find(" ... (800 characters) ... ");
  ASSERT_NE(m, std::string::npos) << cut_accents;
  const std::string head = cut_accents.substr(0, m), tail = cut_accents.substr(m + 26);
  EXPECT_EQ(head.size() % 2, 0u);
  EXPECT_EQ(tail.size() % 2, 0u);
  EXPECT_EQ(head.find("\\x"), std::string::npos);
  EXPECT_EQ(tail.find("\\x"), std::string::npos);
  EXPECT_GT(tail.size(), head.size()) << "the end of the message has the larger share";
}

TEST(PrintableLine, LongPathsLoseTheirMiddleNotTheReason) {
  // A studio path of 290 characters and the reason after it.
  std::string folder = "/studio";
  for (int i = 0; i < 20; ++i) folder += "/sequence_" + std::to_string(100 + i);
  const std::string path = folder + "/cache/dam.0004.ply";
  const std::string message = path + " (frame 4): missing: file not found";
  ASSERT_GT(message.size(), kMaxMessageChars);
  const std::string line = printable_line(message);
  EXPECT_LE(line.size(), kMaxMessageChars);
  EXPECT_TRUE(line.starts_with("/studio/...")) << line;
  EXPECT_TRUE(line.ends_with("/cache/dam.0004.ply (frame 4): missing: file not found")) << line;
  EXPECT_EQ(line.find(" characters)"), std::string::npos) << "the path alone made room: " << line;
  // Two long paths in one message: both keep their file names.
  const std::string two = "cannot rename " + path + " to " + folder + "/out/dam.color.0004.exr: Permission denied";
  const std::string both = printable_line(two);
  EXPECT_LE(both.size(), kMaxMessageChars);
  EXPECT_TRUE(both.starts_with("cannot rename /studio/")) << both;
  EXPECT_NE(both.find("dam.0004.ply to /studio/"), std::string::npos) << both;
  EXPECT_TRUE(both.ends_with("/out/dam.color.0004.exr: Permission denied")) << both;
  // A path longer than the file system takes (one 5,000-character name):
  // the reason after it stays.
  const std::string huge = "/tmp/" + std::string(5000, 'x') + ".ply: File name too long";
  const std::string huge_line = printable_line(huge);
  EXPECT_LE(huge_line.size(), kMaxMessageChars);
  EXPECT_TRUE(huge_line.starts_with("/tmp/")) << huge_line;
  EXPECT_TRUE(huge_line.ends_with("xxx.ply: File name too long")) << huge_line;
}
