#include "lapflow/io/direct_file.hpp"

#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <vector>

namespace lapflow {
namespace {

// O_DIRECT wants the buffer, the offset and the length aligned to the
// device's logical block (512 or 4096 bytes): 4096 serves both.
constexpr std::size_t kAlign = 4096;
// One write call per block: large enough that the syscalls do not count.
constexpr std::size_t kBlock = std::size_t(4) << 20;
// Below this a file goes through stdio: a block's setup is not worth it.
constexpr std::size_t kDirectMin = std::size_t(1) << 20;

std::size_t round_up(std::size_t n) { return (n + kAlign - 1) / kAlign * kAlign; }

// Blocks are reused from file to file: a fresh 4 MiB would be faulted in
// page by page for every file, the cost this file exists to avoid.
class BlockPool {
 public:
  char* take() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!free_.empty()) {
        char* b = free_.back();
        free_.pop_back();
        return b;
      }
    }
    return static_cast<char*>(std::aligned_alloc(kAlign, kBlock));
  }
  void give(char* b) {
    if (!b) return;
    const std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(b);
  }
  ~BlockPool() {
    for (char* b : free_) std::free(b);
  }

 private:
  std::mutex mutex_;
  std::vector<char*> free_;
};

BlockPool& pool() {
  static BlockPool p;
  return p;
}

// pwrite until all of it is written; false with errno set on failure.
bool pwrite_all(int fd, const char* data, std::size_t n, uint64_t offset) {
  while (n > 0) {
    const ssize_t w = ::pwrite(fd, data, n, off_t(offset));
    if (w < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    if (w == 0) {
      errno = EIO;
      return false;
    }
    data += w, n -= std::size_t(w), offset += uint64_t(w);
  }
  return true;
}

// A process with a file-size limit: a block padded to the alignment could
// cross the limit where the file itself would not (the last block of a
// file just under it), so such a process writes through the cache.
bool file_size_limited() {
  rlimit limit{};
  return ::getrlimit(RLIMIT_FSIZE, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY;
}

std::atomic<bool>& direct_io_switch() {
  static std::atomic<bool> on = [] {
    const char* v = std::getenv("LAPFLOW_DIRECT_IO");
    return !(v && std::strcmp(v, "0") == 0);
  }();
  return on;
}

}  // namespace

bool direct_io_enabled() { return direct_io_switch().load(std::memory_order_relaxed); }

void set_direct_io(bool on) { direct_io_switch().store(on, std::memory_order_relaxed); }

DirectFile::DirectFile(const std::string& path, bool try_direct) {
  const int flags = O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC;
  if (try_direct && !file_size_limited()) {
    fd_ = ::open(path.c_str(), flags | O_DIRECT, 0666);
    direct_ = fd_ >= 0;
  }
  // Without O_DIRECT: it was not asked for, or the file system refused it
  // (EINVAL); any other error comes back the same way.
  if (fd_ < 0) fd_ = ::open(path.c_str(), flags, 0666);
  if (fd_ < 0) {
    error_ = errno;
    return;
  }
  buffer_ = pool().take();
  if (!buffer_) fail(ENOMEM);
}

DirectFile::~DirectFile() {
  if (fd_ >= 0) ::close(fd_);
  pool().give(buffer_);
}

bool DirectFile::fail(int err) {
  if (error_ == 0) error_ = err;
  return false;
}

bool DirectFile::write_at(const void* data, std::size_t n, uint64_t offset) {
  if (!ok()) return false;
  const char* src = static_cast<const char*>(data);
  while (n > 0) {
    const uint64_t block = offset / kBlock;
    if (block != block_ && !load(block)) return false;
    const std::size_t at = std::size_t(offset - block * kBlock);
    const std::size_t k = std::min(n, kBlock - at);
    if (at > filled_) std::memset(buffer_ + filled_, 0, at - filled_);
    std::memcpy(buffer_ + at, src, k);
    filled_ = std::max(filled_, at + k);
    dirty_ = true;
    src += k, n -= k, offset += k;
    size_ = std::max(size_, offset);
  }
  return true;
}

// Makes `block` the buffered one: the current block goes to the file first,
// and a block written before (a seek back, as OpenEXR's to its offset table)
// is read back so that what is not overwritten stays.
bool DirectFile::load(uint64_t block) {
  if (!flush()) return false;
  block_ = block, filled_ = 0;
  const uint64_t start = block * kBlock;
  if (start >= on_disk_) return true;
  const std::size_t want = std::size_t(std::min<uint64_t>(kBlock, on_disk_ - start));
  std::size_t got = 0;
  while (got < want) {
    // Direct reads need the aligned length too; past the end they stop short.
    const ssize_t r = ::pread(fd_, buffer_ + got, direct_ ? round_up(want - got) : want - got, off_t(start + got));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return fail(errno);
    if (r == 0) break;
    got += std::size_t(r);
  }
  filled_ = std::min(got, want);
  return true;
}

bool DirectFile::flush() {
  if (!dirty_) return true;
  if (!write_block(filled_)) return false;
  on_disk_ = std::max(on_disk_, block_ * kBlock + filled_);
  dirty_ = false;
  return true;
}

bool DirectFile::write_block(std::size_t length) {
  const uint64_t offset = block_ * kBlock;
  // Direct: padded to the alignment with what the buffer holds there (the
  // file is cut to its size on close).
  if (direct_) {
    if (length < round_up(length)) std::memset(buffer_ + length, 0, round_up(length) - length);
    if (pwrite_all(fd_, buffer_, round_up(length), offset)) return true;
    // Refused (an alignment this device does not take, a full disk, ...):
    // from here on through the cache, which also gives the usual error.
    const int flags = ::fcntl(fd_, F_GETFL);
    if (flags < 0 || ::fcntl(fd_, F_SETFL, flags & ~O_DIRECT) < 0) return fail(errno);
    direct_ = false;
  }
  return pwrite_all(fd_, buffer_, length, offset) || fail(errno);
}

bool DirectFile::close() {
  if (fd_ < 0) return error_ == 0;
  bool done = flush();
  // The padding of the last direct block goes; a gap left at the end by a
  // write past it reads as zeros.
  if (done && ::ftruncate(fd_, off_t(size_)) != 0) done = fail(errno);
  if (::close(fd_) != 0 && done) fail(errno);
  fd_ = -1;
  pool().give(buffer_);
  buffer_ = nullptr;
  return error_ == 0;
}

WholeFileResult write_whole_file(const std::string& path, const void* data, std::size_t n) {
  if (n >= kDirectMin && direct_io_enabled()) {
    DirectFile f(path);
    if (!f.ok()) return {f.error(), true};
    f.write_at(data, n, 0);
    f.close();
    return {f.error(), false};
  }
  // stdio: errno says why a write failed.
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return {errno, true};
  const bool written = std::fwrite(data, 1, n, f) == n && std::fflush(f) == 0;
  const int write_errno = errno;
  const bool closed = std::fclose(f) == 0;
  if (!written) return {write_errno ? write_errno : EIO, false};
  return {closed ? 0 : (errno ? errno : EIO), false};
}

}  // namespace lapflow
