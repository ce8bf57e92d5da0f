#pragma once
/// \file file_lock.hpp An advisory lock on a file that the kernel drops when
/// its holder ends, however it ends (kill -9 too): a lock whose owner is dead
/// is free to the next process. Held with flock(2), which Linux's NFS client
/// maps to POSIX locks, so render jobs on several nodes of a farm see each
/// other's locks in a shared folder. The file holds its owner (process id,
/// host name, and what it is doing) for the message of a process that finds
/// it taken.
#include <chrono>
#include <optional>
#include <string>
#include <variant>

namespace lapflow {

/// Who holds a lock, as its file says.
struct LockOwner {
  long pid = 0;
  std::string host;     ///< the host name
  std::string purpose;  ///< what the holder wrote: e.g. the digest of its render options
  /// "pid 1234 on node7"
  std::string describe() const;
};

class FileLock {
 public:
  /// Takes the lock at `path` (creating the file) without waiting and writes
  /// this process and `purpose` into it; or, when another process holds it,
  /// returns that owner. Throws OutputError naming `path` when the file
  /// cannot be created.
  static std::variant<FileLock, LockOwner> try_take(const std::string& path, const std::string& purpose);
  /// try_take until the lock is free, for at most `patience`; the owner
  /// when it is still held then. For short critical sections (a file that
  /// several processes rewrite in turn).
  static std::variant<FileLock, LockOwner> take_within(const std::string& path, const std::string& purpose,
                                                       std::chrono::milliseconds patience);
  FileLock(FileLock&& other) noexcept;
  FileLock& operator=(FileLock&& other) noexcept;
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;
  /// Releases the lock and removes its file.
  ~FileLock();
  void release();
  const std::string& path() const { return path_; }

 private:
  FileLock(std::string path, int fd) : path_(std::move(path)), fd_(fd) {}
  std::string path_;
  int fd_ = -1;
};

/// The owner a lock file names, if it can be read (a held lock or a stale
/// file). For messages and `farm status`.
std::optional<LockOwner> read_lock_owner(const std::string& path);

}  // namespace lapflow
