#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace {
std::string compose(const std::string& file, const std::string& message, std::optional<int> frame) {
  std::string s = file.empty() ? std::string("<input>") : file;
  if (frame) s += " (frame " + std::to_string(*frame) + ")";
  return s + ": " + message;
}
}  // namespace

InputError::InputError(const std::string& file, const std::string& message, std::optional<int> frame)
    : std::runtime_error(compose(file, message, frame)), file_(file), message_(message), frame_(frame) {}

}  // namespace lapflow
