#pragma once
/// \file direct_file.hpp Large outputs written around the page cache.
///
/// A bake writes hundreds of megabytes a frame. Through the page cache the
/// kernel copies every byte into cache pages it allocates first, which on
/// a virtual machine can cost far more than the copy (docs/performance.md,
/// "EXR writing and compression"). A
/// DirectFile collects the writes in an aligned block and hands the kernel
/// whole blocks with O_DIRECT, which it moves to the disk without a copy.
/// Where the file system refuses O_DIRECT (tmpfs, some network and FUSE
/// file systems), where a direct write fails, or where the process has a
/// file-size limit, it writes through the page cache as before: the file's
/// bytes never depend on the path taken.
#include <cstddef>
#include <cstdint>
#include <string>

namespace lapflow {

/// Whether outputs go around the page cache: yes unless the environment
/// variable LAPFLOW_DIRECT_IO is "0" (read at the first call) or
/// set_direct_io(false) was called.
bool direct_io_enabled();

/// Turns direct writes on or off for the files opened from now on.
void set_direct_io(bool on);

/// A file created (or truncated) for writing at any offset, in any order.
/// Not thread-safe; one writer at a time.
class DirectFile {
 public:
  /// Opens `path`; `try_direct`: around the page cache where it can. On
  /// failure ok() is false and error() holds the errno.
  explicit DirectFile(const std::string& path, bool try_direct = direct_io_enabled());
  /// Closes without reporting (call close() to know whether it worked).
  ~DirectFile();
  DirectFile(const DirectFile&) = delete;
  DirectFile& operator=(const DirectFile&) = delete;

  /// Open, and no write or close failed.
  bool ok() const { return fd_ >= 0 && error_ == 0; }
  /// The errno of the first failure, 0 if none.
  int error() const { return error_; }
  /// Whether writes still go around the page cache.
  bool direct() const { return direct_; }
  /// The end of the furthest write: the file's size once closed.
  uint64_t size() const { return size_; }

  /// Writes `n` bytes at `offset` (also over earlier bytes, or past the end:
  /// a gap reads as zeros). False on failure (error()).
  bool write_at(const void* data, std::size_t n, uint64_t offset);

  /// Writes what is still buffered, sets the file's size and closes it. False
  /// if that or any earlier write failed. Idempotent.
  bool close();

 private:
  bool flush();
  bool load(uint64_t block);
  bool write_block(std::size_t length);
  bool fail(int err);

  int fd_ = -1;
  int error_ = 0;
  bool direct_ = false;
  char* buffer_ = nullptr;     ///< one aligned block, from a pool
  uint64_t block_ = UINT64_MAX;  ///< the block in buffer_ (UINT64_MAX: none)
  std::size_t filled_ = 0;     ///< valid bytes at the start of buffer_
  bool dirty_ = false;
  uint64_t on_disk_ = 0;       ///< bytes [0, on_disk_) have been written to the file
  uint64_t size_ = 0;
};

/// What write_whole_file did: the errno of a failure (0: none), and whether
/// it failed to create the file at all.
struct WholeFileResult {
  int error = 0;
  bool at_open = false;
};

/// Writes `n` bytes to a new file `path` (a DirectFile for large contents,
/// stdio for small ones).
WholeFileResult write_whole_file(const std::string& path, const void* data, std::size_t n);

}  // namespace lapflow
