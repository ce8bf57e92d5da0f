#include "lapflow/core/errors.hpp"

#include <csignal>

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

InputError::InputError(const std::string& file, const std::string& message, std::optional<int> frame)
    : std::runtime_error(compose(file, message, frame)), file_(file), message_(message), frame_(frame) {}

Interrupted::Interrupted(int signal, std::optional<int> last_complete_frame)
    : std::runtime_error(stop_message(signal, last_complete_frame)),
      signal_(signal),
      last_complete_frame_(last_complete_frame) {}

}  // namespace lapflow
