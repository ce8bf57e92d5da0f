#pragma once
/// \file errors.hpp Exceptions for bad input, output failures and stops.
/// Only the CLI catches them and turns them into an exit code: 2 for bad
/// input, usage and output problems, 128 + signal for a stop, 1 for anything
/// else.
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace lapflow {

/// A piece of an input file as an error message quotes it, in single quotes:
/// at most 40 characters (a 5 MB number must not make a 5 MB message), bytes
/// that are not printable ASCII escaped as \xHH.
std::string quote_token(std::string_view token);

/// The longest line lapflow prints for an error or warning, in bytes.
inline constexpr std::size_t kMaxMessageChars = 300;

/// `text` as one printable line of at most `max_chars` bytes: trailing
/// blanks dropped; control characters (a newline too) and bytes that are not
/// valid UTF-8 escaped as \xHH, valid UTF-8 kept (a path or a unit such as
/// m² stays readable). A longer line first loses the middle of its longest
/// paths ("/studio/.../shot/dam.0004.ply"), then, when that is not enough,
/// the middle of the line (" ... (N characters) ... ", N the length of
/// `text`): the start, which names the file, and the end, which says what is
/// wrong, are kept. The CLI prints every error through it, whatever
/// a library or an input file put in the message.
std::string printable_line(std::string_view text, std::size_t max_chars = kMaxMessageChars);

/// Malformed or missing input. what() is one line naming the file, the frame
/// when known, the element, and what is wrong:
/// `dam.0004.ply (frame 4): vertex 1207: velocity is NaN`.
class InputError : public std::runtime_error {
 public:
  InputError(const std::string& file, const std::string& message,
             std::optional<int> frame = std::nullopt);
  const std::string& file() const { return file_; }
  const std::string& message() const { return message_; }
  std::optional<int> frame() const { return frame_; }
  /// The same error with the frame number filled in (for sequence readers).
  InputError with_frame(int frame) const { return InputError(file_, message_, frame); }

 private:
  std::string file_, message_;
  std::optional<int> frame_;
};

/// A usage mistake on the command line or in a scene file (exit code 2).
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Failure writing an output (disk full, file too large, permission, --out
/// not a folder): exit code 2. what() names the file or folder and the
/// system's reason.
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A run that SIGINT or SIGTERM asked to stop, stopped between frames with
/// every frame's files either all in place or all absent: exit code
/// 128 + signal. what(): `stopped by SIGTERM; the last complete frame is 12`.
class Interrupted : public std::runtime_error {
 public:
  Interrupted(int signal, std::optional<int> last_complete_frame);
  int signal() const { return signal_; }
  std::optional<int> last_complete_frame() const { return last_complete_frame_; }

 private:
  int signal_;
  std::optional<int> last_complete_frame_;
};

}  // namespace lapflow
