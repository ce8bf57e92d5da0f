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

namespace {

/// The printable pieces of text[begin, end): one per character (a UTF-8
/// character kept, any other byte escaped), so that a cut never splits an
/// escape or a character. `begin` must start a character.
std::vector<std::string> escaped_pieces(std::string_view text, std::size_t begin, std::size_t end) {
  std::vector<std::string> pieces;
  for (std::size_t i = begin; i < end;) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    std::string piece;
    std::size_t n = 1;
    if (c >= 0x20 && c < 0x7f) piece = char(c);
    else if (c >= 0x80 && (n = printable_utf8_length(text, i)) > 0) piece = std::string(text.substr(i, n));
    else n = 1, append_hex(piece, c);
    pieces.push_back(std::move(piece));
    i += n;
  }
  return pieces;
}

std::size_t total_size(const std::vector<std::string>& pieces) {
  std::size_t n = 0;
  for (const std::string& p : pieces) n += p.size();
  return n;
}

/// Where each character a path may hold stops: blanks, quotes, brackets.
bool ends_path(char c) {
  return c == ' ' || c == '\t' || c == '\'' || c == '"' || c == '(' || c == ')' || c == '[' || c == ']' ||
         c == ',' || c == ';';
}

/// `text` with its longest paths (words holding a '/') shortened in their
/// middle, "/studio/.../shot/dam.0004.ply", until it is at most `target`
/// bytes or no path can lose more: each keeps its first folder and at least
/// its last 40 bytes (the file name whole when it fits).
std::string shorten_paths(std::string_view text, std::size_t target) {
  std::string s(text);
  constexpr std::size_t kKeepTail = 40, kMarker = 3;  // "..."
  for (;;) {
    if (s.size() <= target) return s;
    // The longest shortenable path.
    std::size_t best_begin = 0, best_end = 0;
    for (std::size_t i = 0; i < s.size();) {
      if (ends_path(s[i])) {
        ++i;
        continue;
      }
      std::size_t j = i;
      while (j < s.size() && !ends_path(s[j])) ++j;
      std::size_t end = j;
      while (end > i && s[end - 1] == ':') --end;  // "path: reason"
      const std::string_view word(s.data() + i, end - i);
      const std::size_t head = word.find('/', word.size() > 1 ? 1 : 0);
      if (word.find('/') != std::string_view::npos && head != std::string_view::npos &&
          word.size() > head + 1 + kMarker + kKeepTail && end - i > best_end - best_begin)
        best_begin = i, best_end = end;
      i = j;
    }
    if (best_end == best_begin) return s;
    const std::string_view word(s.data() + best_begin, best_end - best_begin);
    const std::size_t head = word.find('/', word.size() > 1 ? 1 : 0) + 1;  // "/studio/"
    const std::size_t excess = s.size() - target;
    const std::size_t removable = word.size() - head - kMarker - kKeepTail;
    if (removable == 0) return s;
    // Cut from after the head; the kept tail starts at a '/' when one is near.
    std::size_t cut_end = head + std::min(removable, excess) + kMarker;
    if (const std::size_t slash = word.find('/', cut_end); slash != std::string_view::npos &&
                                                            slash - cut_end < 16 &&
                                                            word.size() - slash >= kKeepTail / 2)
      cut_end = slash;
    while (cut_end < word.size() && (static_cast<unsigned char>(word[cut_end]) & 0xc0) == 0x80) ++cut_end;
    if (cut_end <= head + kMarker) return s;
    std::string shorter = std::string(word.substr(0, head)) + "..." + std::string(word.substr(cut_end));
    s.replace(best_begin, best_end - best_begin, shorter);
  }
}

}  // namespace

std::string printable_line(std::string_view text, std::size_t max_chars) {
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ' || text.back() == '\t'))
    text.remove_suffix(1);
  // Escaping never shortens: a text far over the limit is cut without
  // escaping all of it (a 5 MB message).
  if (text.size() <= 4 * max_chars) {
    std::string shortened = shorten_paths(text, max_chars);
    std::vector<std::string> pieces = escaped_pieces(shortened, 0, shortened.size());
    if (total_size(pieces) <= max_chars) {
      std::string out;
      for (const std::string& p : pieces) out += p;
      return out;
    }
  }
  // Still too long: the middle goes, the start (the file) and the end (the
  // reason) stay. A third of the room for the start, the rest for the end.
  const std::string marker = " ... (" + std::to_string(text.size()) + " characters) ... ";
  const std::size_t room = max_chars > marker.size() ? max_chars - marker.size() : 0;
  const std::size_t head_room = room / 3, tail_room = room - head_room;
  std::string head;
  for (const std::string& p : escaped_pieces(text, 0, std::min(text.size(), head_room))) {
    if (head.size() + p.size() > head_room) break;
    head += p;
  }
  // The tail from a character boundary near its end, then pieces dropped
  // from its front until it fits.
  std::size_t from = text.size() > tail_room ? text.size() - tail_room : 0;
  while (from > 0 && from < text.size() && (static_cast<unsigned char>(text[from]) & 0xc0) == 0x80) ++from;
  std::vector<std::string> tail_pieces = escaped_pieces(text, from, text.size());
  std::size_t tail_size = total_size(tail_pieces), first = 0;
  while (tail_size > tail_room && first < tail_pieces.size()) tail_size -= tail_pieces[first++].size();
  std::string tail;
  for (std::size_t i = first; i < tail_pieces.size(); ++i) tail += tail_pieces[i];
  return head + marker + tail;
}

InputError::InputError(const std::string& file, const std::string& message, std::optional<int> frame)
    : std::runtime_error(compose(file, message, frame)), file_(file), message_(message), frame_(frame) {}

Interrupted::Interrupted(int signal, std::optional<int> last_complete_frame)
    : std::runtime_error(stop_message(signal, last_complete_frame)),
      signal_(signal),
      last_complete_frame_(last_complete_frame) {}

}  // namespace lapflow
