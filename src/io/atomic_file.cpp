#include "lapflow/io/atomic_file.hpp"

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace fs = std::filesystem;

void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
  static std::atomic<unsigned> counter{0};
  const fs::path target(path);
  // Same folder (rename is atomic only within a file system), hidden, unique
  // per process and call, and ending in the target's extension.
  const std::string tmp = (target.parent_path() /
                           ("." + target.stem().string() + ".tmp" + std::to_string(::getpid()) + "_" +
                            std::to_string(counter++) + target.extension().string()))
                              .string();
  try {
    write(tmp);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  std::error_code ec;
  fs::rename(tmp, target, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw OutputError(path + ": cannot move the finished file into place: " + ec.message());
  }
}

void write_text_atomically(const std::string& path, const std::string& content) {
  write_atomically(path, [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw OutputError(path + ": cannot open for writing");
    out.write(content.data(), std::streamsize(content.size()));
    out.close();
    if (!out) throw OutputError(path + ": write failed (disk full?)");
  });
}

}  // namespace lapflow
