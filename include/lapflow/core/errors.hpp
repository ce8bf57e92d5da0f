#pragma once
/// \file errors.hpp Exceptions for bad input. Only the CLI catches them and
/// turns them into exit code 2 (bad input) or 1 (anything else).
#include <optional>
#include <stdexcept>
#include <string>

namespace lapflow {

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

/// Failure writing an output (disk full, permission): exit code 1.
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace lapflow
