#pragma once
/// \file atomic_file.hpp Every output is written to a temporary name in the
/// destination folder and renamed, so an interrupted run never leaves a half
/// file and never damages an earlier one.
#include <functional>
#include <string>

namespace lapflow {

/// Calls `write(tmp_path)`, then renames tmp_path to `path`. On any exception
/// the temporary file is removed and the exception propagates; `path` is
/// untouched. Throws OutputError when the rename fails. The temporary name
/// keeps the final extension (OIIO picks the format from it).
void write_atomically(const std::string& path, const std::function<void(const std::string& tmp_path)>& write);

/// Writes a text file atomically.
void write_text_atomically(const std::string& path, const std::string& content);

}  // namespace lapflow
