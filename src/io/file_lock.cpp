// Advisory per-file locks with flock(2), released by the kernel when their
// holder ends.
#include "lapflow/io/file_lock.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <system_error>
#include <thread>

#include "lapflow/core/errors.hpp"

namespace lapflow {
namespace {

std::string host_name() {
  char name[256] = {};
  if (::gethostname(name, sizeof name - 1) != 0) return "?";
  return name;
}

std::optional<LockOwner> parse_owner(const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return std::nullopt;
  LockOwner o;
  const auto pid = j.find("pid");
  const auto host = j.find("host");
  const auto purpose = j.find("purpose");
  if (pid == j.end() || !pid->is_number_integer() || host == j.end() || !host->is_string()) return std::nullopt;
  o.pid = pid->get<long>();
  o.host = host->get<std::string>();
  if (purpose != j.end() && purpose->is_string()) o.purpose = purpose->get<std::string>();
  return o;
}

std::string read_all(int fd) {
  std::string text;
  char buffer[4096];
  ::lseek(fd, 0, SEEK_SET);
  for (ssize_t n; (n = ::read(fd, buffer, sizeof buffer)) > 0;) text.append(buffer, std::size_t(n));
  return text;
}

}  // namespace

std::string LockOwner::describe() const { return "pid " + std::to_string(pid) + " on " + host; }

std::variant<FileLock, LockOwner> FileLock::try_take(const std::string& path, const std::string& purpose) {
  for (int attempt = 0;; ++attempt) {
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) throw OutputError(path + ": cannot create the lock file: " + std::strerror(errno));
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      std::optional<LockOwner> owner = parse_owner(read_all(fd));
      ::close(fd);
      if (error != EWOULDBLOCK)
        throw OutputError(path + ": cannot lock the file: " + std::strerror(error));
      // Held: its owner is writing its name in, or it is named.
      return owner ? *owner : LockOwner{0, "another host", ""};
    }
    // Ours, unless its holder removed the file between our open and our
    // lock (then the lock is on a file nobody else will see): try again.
    struct stat held {}, named {};
    if (::fstat(fd, &held) != 0 || ::stat(path.c_str(), &named) != 0 || held.st_ino != named.st_ino ||
        held.st_dev != named.st_dev) {
      ::close(fd);
      if (attempt < 100) continue;
      throw OutputError(path + ": cannot lock the file: it keeps being replaced");
    }
    const std::string text =
        nlohmann::json{{"pid", long(::getpid())}, {"host", host_name()}, {"purpose", purpose}}.dump() + "\n";
    if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, text.data(), text.size(), 0) != ssize_t(text.size())) {
      const int error = errno;
      ::unlink(path.c_str());
      ::close(fd);
      throw OutputError(path + ": cannot write the lock file: " + std::strerror(error));
    }
    return FileLock(path, fd);
  }
}

std::variant<FileLock, LockOwner> FileLock::take_within(const std::string& path, const std::string& purpose,
                                                        std::chrono::milliseconds patience) {
  const auto until = std::chrono::steady_clock::now() + patience;
  for (;;) {
    auto taken = try_take(path, purpose);
    if (std::holds_alternative<FileLock>(taken) || std::chrono::steady_clock::now() >= until) return taken;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

FileLock::FileLock(FileLock&& other) noexcept : path_(std::move(other.path_)), fd_(other.fd_) { other.fd_ = -1; }

FileLock& FileLock::operator=(FileLock&& other) noexcept {
  if (this != &other) {
    release();
    path_ = std::move(other.path_);
    fd_ = other.fd_;
    other.fd_ = -1;
  }
  return *this;
}

FileLock::~FileLock() { release(); }

void FileLock::release() {
  if (fd_ < 0) return;
  // Removed while still held: a process that opened the old file finds, once
  // it has the lock, that the name is gone, and opens again.
  ::unlink(path_.c_str());
  ::close(fd_);
  fd_ = -1;
}

std::optional<LockOwner> read_lock_owner(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  return parse_owner(std::string{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()});
}

}  // namespace lapflow
