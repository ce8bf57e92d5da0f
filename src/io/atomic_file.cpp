#include "lapflow/io/atomic_file.hpp"

#include <signal.h>
#include <sys/resource.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <regex>
#include <system_error>

#include <fmt/format.h>
#include <zlib.h>

#include "lapflow/core/errors.hpp"
#include "lapflow/io/direct_file.hpp"

namespace lapflow {
namespace fs = std::filesystem;
namespace {

/// `DIR/.STEM.tmpHOST-PID_K.EXT` for `DIR/STEM.EXT`: same folder (rename is
/// atomic only within a file system), hidden, unique per host, process and
/// call, ending in the target's extension.
std::string temporary_path(const std::string& path) {
  static std::atomic<unsigned> counter{0};
  const fs::path target(path);
  const std::string name = fmt::format(".{}.tmp{}-{}_{}{}", target.stem().string(), temporary_host_tag(), ::getpid(),
                                      counter++, target.extension().string());
  return (target.parent_path() / name).string();
}

/// Whether process `pid` of this host is running (or may be: a process of
/// another user answers EPERM).
bool process_running(pid_t pid) { return pid > 0 && (::kill(pid, 0) == 0 || errno == EPERM); }

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

const std::string& temporary_host_tag() {
  // What makes a process id mean one process: the host, its boot (ids start
  // again after a reboot) and the PID namespace (a container's ids are its
  // own). A CRC, as the manifest's digests: the tag only has to tell a
  // farm's hosts apart.
  static const std::string tag = [] {
    std::array<char, 256> name{};
    if (::gethostname(name.data(), name.size() - 1) != 0) name[0] = '\0';
    std::string key = name.data();
    std::error_code ec;
    key += "|" + fs::read_symlink("/proc/self/ns/pid", ec).string();
    if (std::FILE* f = std::fopen("/proc/sys/kernel/random/boot_id", "rb")) {
      std::array<char, 64> boot{};
      key += "|" + std::string(boot.data(), std::fread(boot.data(), 1, boot.size(), f));
      std::fclose(f);
    }
    const uLong crc = crc32(crc32(0, nullptr, 0), reinterpret_cast<const Bytef*>(key.data()), uInt(key.size()));
    return fmt::format("{:08x}", std::uint32_t(crc));
  }();
  return tag;
}

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
    // Large contents (a frame's patch state, its OBJ) around the page cache.
    const WholeFileResult r = write_whole_file(tmp, content.data(), content.size());
    if (r.error != 0)
      throw OutputError(path + (r.at_open ? ": cannot open for writing: " : ": write failed: ") +
                        std::generic_category().message(r.error));
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

std::vector<std::pair<std::string, std::uintmax_t>> StagedFiles::sizes() {
  const std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::pair<std::string, std::uintmax_t>> out;
  for (const Entry& e : entries_) {
    std::error_code ec;
    const std::uintmax_t size = fs::file_size(e.tmp, ec);
    if (ec) throw OutputError(e.tmp + ": cannot read the size of the file just written: " + ec.message());
    out.emplace_back(e.path, size);
  }
  std::sort(out.begin(), out.end());
  return out;
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
                                                  const std::vector<std::string>& stem_patterns,
                                                  std::chrono::seconds foreign_age) {
  std::string alternatives;
  for (const std::string& p : stem_patterns) alternatives += (alternatives.empty() ? "" : "|") + p;
  // The shape temporary_path() gives, .STEM.tmpHOST-PID_K.EXT, the one
  // before the host tag, .STEM.tmpPID_K.EXT, and OpenImageIO's texture
  // maker's own temporary beside ours, .STEM.tmpHOST-PID_K.XXXXXXXX.temp.EXT.
  const std::regex stale("\\.(?:" + alternatives +
                         ")\\.tmp(?:([0-9a-f]{8})-)?([0-9]+)_[0-9]+(?:\\.[0-9a-f]{8}\\.temp)?(?:\\.[A-Za-z0-9]+)?");
  const auto now = fs::file_time_type::clock::now();
  std::vector<std::string> removed;
  std::error_code ec;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    std::smatch m;
    if (name.empty() || name[0] != '.' || !std::regex_match(name, m, stale)) continue;
    // A running process's file is being written (a farm's render beside a
    // tracking chunk, both in one folder): never taken from under it.
    // The host and the process id are the last two groups (a stem pattern
    // may have its own).
    const auto& host = m[m.size() - 2];
    const auto& pid = m[m.size() - 1];
    bool dead;
    if (host.matched && host.str() == temporary_host_tag()) {
      // Nine digits fit a pid_t (a longer id is left alone).
      dead = pid.length() <= 9 && !process_running(pid_t(std::stol(pid.str())));
    } else {
      std::error_code tec;
      const auto written = fs::last_write_time(entry.path(), tec);
      dead = !tec && now - written > foreign_age;
    }
    if (!dead) continue;
    if (std::error_code rm; fs::remove(entry.path(), rm)) removed.push_back(name);
  }
  std::sort(removed.begin(), removed.end());
  return removed;
}

}  // namespace lapflow
