#include "lapflow/core/errors.hpp"

#include <csignal>
#include <cstdint>
#include <utility>
#include <vector>

namespace lapflow {
namespace {
std::string compose(const std::string& file, const std::string& message, std::optional<int> frame) {
  std::string s = file.empty() ? std::string("<input>") : file;
  if (frame) s += " (frame " + std::to_string(*frame) + ")";
  return s + ": " + message;
}

std::string stop_message(int signal, std::optional<int> last) {
  const std::string name = signal == SIGINT ? "SIGINT" : signal == SIGTERM ? "SIGTERM" : "signal " + std::to_string(signal);
  return "stopped by " + name + "; " +
         (last ? "the last complete frame is " + std::to_string(*last) : std::string("no frame is complete"));
}
}  // namespace

std::string quote_token(std::string_view token) {
  constexpr std::size_t kShown = 40;
  std::string out = "'";
  for (unsigned char c : token.substr(0, kShown)) {
    if (c >= 0x20 && c < 0x7f) {
      out += char(c);
    } else {
      constexpr char hex[] = "0123456789abcdef";
      out += "\\x";
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  out += token.size() > kShown ? "...' (" + std::to_string(token.size()) + " characters)" : std::string("'");
  return out;
}

namespace {

void append_hex(std::string& out, unsigned char c) {
  constexpr char hex[] = "0123456789abcdef";
  out += "\\x";
  out += hex[c >> 4];
  out += hex[c & 15];
}

/// Length of the well-formed UTF-8 sequence of a printable character at
/// text[i] (no overlong form, surrogate or C1 control), else 0.
std::size_t printable_utf8_length(std::string_view text, std::size_t i) {
  const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(text[k]); };
  const unsigned char c = byte(i);
  std::size_t n = 0;
  uint32_t cp = 0;
  if (c >= 0xc2 && c <= 0xdf) n = 2, cp = c & 0x1fu;
  else if (c >= 0xe0 && c <= 0xef) n = 3, cp = c & 0x0fu;
  else if (c >= 0xf0 && c <= 0xf4) n = 4, cp = c & 0x07u;
  else return 0;
  if (i + n > text.size()) return 0;
  for (std::size_t k = 1; k < n; ++k) {
    if ((byte(i + k) & 0xc0) != 0x80) return 0;
    cp = cp << 6 | (byte(i + k) & 0x3fu);
  }
  const bool overlong = (n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000);
  if (overlong || (cp >= 0xd800 && cp <= 0xdfff) || cp > 0x10ffff || cp < 0xa0) return 0;
  return n;
}

}  // namespace

std::string printable_line(std::string_view text, std::size_t max_chars) {
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ' || text.back() == '\t'))
    text.remove_suffix(1);
  // Escaped piece by piece, with the text position after each, so that a cut
  // never splits an escape or a UTF-8 character.
  std::string out;
  std::vector<std::pair<std::size_t, std::size_t>> ends;  // (bytes of out, bytes of text)
  for (std::size_t i = 0; i < text.size();) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += char(c);
      ++i;
    } else if (const std::size_t n = c >= 0x80 ? printable_utf8_length(text, i) : 0; n > 0) {
      out.append(text.substr(i, n));
      i += n;
    } else {
      append_hex(out, c);
      ++i;
    }
    ends.emplace_back(out.size(), i);
    // Far enough past the limit to decide: stop escaping a 5 MB message.
    if (out.size() > max_chars + 4) break;
  }
  if (out.size() <= max_chars && (ends.empty() || ends.back().second == text.size())) return out;
  const std::string tail = "... (" + std::to_string(text.size()) + " characters)";
  const std::size_t room = max_chars > tail.size() ? max_chars - tail.size() : 0;
  std::size_t keep = 0;
  for (const auto& [bytes, consumed] : ends)
    if (bytes <= room) keep = bytes;
  out.resize(keep);
  return out + tail;
}

InputError::InputError(const std::string& file, const std::string& message, std::optional<int> frame)
    : std::runtime_error(compose(file, message, frame)), file_(file), message_(message), frame_(frame) {}

Interrupted::Interrupted(int signal, std::optional<int> last_complete_frame)
    : std::runtime_error(stop_message(signal, last_complete_frame)),
      signal_(signal),
      last_complete_frame_(last_complete_frame) {}

}  // namespace lapflow
