#include "lapflow/io/atomic_file.hpp"

#include <sys/resource.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <regex>
#include <system_error>

#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace fs = std::filesystem;
namespace {

/// `DIR/.STEM.tmpPID_K.EXT` for `DIR/STEM.EXT`: same folder (rename is
/// atomic only within a file system), hidden, unique per process and call,
/// ending in the target's extension.
std::string temporary_path(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  const fs::path target(path);
  return (target.parent_path() / ("." + target.stem().string() + ".tmp" + std::to_string(::getpid()) + "_" +
                                  std::to_string(counter++) + target.extension().string()))
      .string();
}

void remove_quietly(const std::string& path) {
  std::error_code ec;
  fs::remove(path, ec);
}

void move_into_place(const std::string& tmp, const std::string& path) {
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) throw OutputError(path + ": cannot move the finished file into place: " + ec.message());
}

}  // namespace

void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write,
                      StagedFiles* staged) {
  if (staged) return staged->write(path, write);
  const std::string tmp = temporary_path(path);
  const TempFileRecord record(tmp);
  try {
    write(tmp);
    move_into_place(tmp, path);
  } catch (...) {
    remove_quietly(tmp);
    throw;
  }
}

void write_text_atomically(const std::string& path, const std::string& content, StagedFiles* staged) {
  write_atomically(path, [&](const std::string& tmp) {
    // stdio rather than a stream: errno says why a write failed.
    std::FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) throw OutputError(path + ": cannot open for writing: " + std::generic_category().message(errno));
    const bool written = std::fwrite(content.data(), 1, content.size(), f) == content.size() && std::fflush(f) == 0;
    const int write_errno = errno;
    const bool closed = std::fclose(f) == 0;
    if (!written || !closed)
      throw OutputError(path + ": write failed: " + std::generic_category().message(written ? errno : write_errno));
  }, staged);
}

StagedFiles::~StagedFiles() { abandon(); }

void StagedFiles::write(const std::string& path, const std::function<void(const std::string&)>& write) {
  Entry e{path, temporary_path(path), nullptr};
  e.record = std::make_unique<TempFileRecord>(e.tmp);  // before the file exists
  try {
    write(e.tmp);
  } catch (...) {
    remove_quietly(e.tmp);
    throw;
  }
  const std::lock_guard<std::mutex> lock(mutex_);
  entries_.push_back(std::move(e));
}

void StagedFiles::commit(const std::string& last) {
  const std::lock_guard<std::mutex> lock(mutex_);
  // `last` is the group's commit file: it goes first (an old one must not
  // vouch for a half-renamed group) and comes back last.
  std::sort(entries_.begin(), entries_.end(), [&](const Entry& a, const Entry& b) {
    if ((a.path == last) != (b.path == last)) return b.path == last;
    return a.path < b.path;
  });
  std::error_code ec;
  fs::remove(last, ec);
  if (ec) throw OutputError(last + ": cannot replace the earlier file: " + ec.message());
  try {
    for (Entry& e : entries_) {
      move_into_place(e.tmp, e.path);
      e.tmp.clear();
      e.record.reset();
    }
  } catch (...) {
    for (const Entry& e : entries_)
      if (!e.tmp.empty()) remove_quietly(e.tmp);
    entries_.clear();
    throw;
  }
  entries_.clear();
}

void StagedFiles::abandon() {
  const std::lock_guard<std::mutex> lock(mutex_);
  for (const Entry& e : entries_)
    if (!e.tmp.empty()) remove_quietly(e.tmp);
  entries_.clear();
}

std::string write_failure_reason(const std::string& path) {
  const fs::path p(path);
  struct statvfs fsinfo {};
  const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
  // Root may also fill the blocks reserved for it.
  if (::statvfs(dir.c_str(), &fsinfo) == 0 && (::geteuid() == 0 ? fsinfo.f_bfree : fsinfo.f_bavail) == 0)
    return std::generic_category().message(ENOSPC);
  rlimit limit{};
  std::error_code ec;
  const std::uintmax_t size = fs::file_size(p, ec);
  if (!ec && ::getrlimit(RLIMIT_FSIZE, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY && size >= limit.rlim_cur)
    return std::generic_category().message(EFBIG);
  return "";
}

std::vector<std::string> remove_stale_temporaries(const std::string& dir,
                                                  const std::vector<std::string>& stem_patterns) {
  std::string alternatives;
  for (const std::string& p : stem_patterns) alternatives += (alternatives.empty() ? "" : "|") + p;
  // The shape temporary_path() gives: .STEM.tmpPID_K.EXT
  const std::regex stale("\\.(" + alternatives + ")\\.tmp[0-9]+_[0-9]+(\\.[A-Za-z0-9]+)?");
  std::vector<std::string> removed;
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || name[0] != '.' || !std::regex_match(name, stale)) continue;
    if (std::error_code rm; fs::remove(entry.path(), rm)) removed.push_back(name);
  }
  std::sort(removed.begin(), removed.end());
  return removed;
}

}  // namespace lapflow
