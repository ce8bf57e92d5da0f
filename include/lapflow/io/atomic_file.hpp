#pragma once
/// \file atomic_file.hpp Every output is written to a temporary name in the
/// destination folder and renamed, so an interrupted run never leaves a half
/// file and never damages an earlier one. The temporary name of `DIR/S.EXT`
/// is `DIR/.S.tmpHOST-PID_K.EXT`: hidden, unique per host (8 hex digits of a
/// hash of its name, boot and PID namespace), process and call, and with the
/// final extension (OIIO picks the format from it).
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "lapflow/core/interrupt.hpp"

namespace lapflow {

class StagedFiles;

/// Calls `write(tmp_path)`, then renames tmp_path to `path`. On any exception
/// the temporary file is removed and the exception propagates; `path` is
/// untouched. Throws OutputError when the rename fails. With `staged`, the
/// file is only written under its temporary name and joins that group, which
/// renames it with the others (StagedFiles::commit).
void write_atomically(const std::string& path, const std::function<void(const std::string& tmp_path)>& write,
                      StagedFiles* staged = nullptr);

/// Writes a text (or binary) file atomically, or into `staged`. Throws
/// OutputError naming `path` and the system's reason (e.g. "File too large",
/// "No space left on device").
void write_text_atomically(const std::string& path, const std::string& content, StagedFiles* staged = nullptr);

/// Files that appear together, such as one baked frame's. Each is written
/// under its temporary name (from several threads if need be); commit()
/// renames them into place, the `last` one after all the others, so that the
/// presence of `last` means the whole group is there. A group destroyed
/// before commit() removes its temporary files. Every temporary file is
/// registered for the hard-stop signal handler (interrupt.hpp).
class StagedFiles {
 public:
  StagedFiles() = default;
  ~StagedFiles();
  StagedFiles(const StagedFiles&) = delete;
  StagedFiles& operator=(const StagedFiles&) = delete;

  /// Writes `path`'s content under its temporary name with `write(tmp)`.
  /// Thread-safe. On an exception the temporary file is removed and the
  /// exception propagates.
  void write(const std::string& path, const std::function<void(const std::string& tmp_path)>& write);

  /// Renames the files into place: first removes an existing `last` (an old
  /// `last` must never stand beside new files), then renames the others in
  /// path order, then `last`. Throws OutputError naming the file that could
  /// not be moved; the temporaries left are removed.
  void commit(const std::string& last);

  /// Removes the temporary files (also done by the destructor).
  void abandon();
  /// The final path and the size in bytes of each file written so far, in
  /// path order (a frame's record of its files, written before commit()).
  std::vector<std::pair<std::string, std::uintmax_t>> sizes();

 private:
  struct Entry {
    std::string path, tmp;
    std::unique_ptr<TempFileRecord> record;
  };
  std::mutex mutex_;
  std::vector<Entry> entries_;
};

/// Why writing `path` (a file being written) may have failed when the
/// library that wrote it does not say: "No space left on device" when its
/// file system has no free block, "File too large" when it reached the
/// process's file-size limit (RLIMIT_FSIZE); "" when neither.
std::string write_failure_reason(const std::string& path);

/// This host's tag in temporary names: 8 hex digits of a hash of its host
/// name, boot id and PID namespace. Render jobs on several nodes (or in
/// containers) may write one --out folder, and a process id means something
/// only where it was given.
const std::string& temporary_host_tag();

/// Removes the temporary files that earlier, killed runs left in `dir` for
/// files whose name (before the extension) is one of `stems` or matches a
/// stem pattern: `stem_patterns` are ECMAScript regexes (`NAME\.color\.\d+`).
/// A file of this host is removed when the process that wrote it is no longer
/// running; one of another host (or without a host tag) when it was last
/// written over `foreign_age` ago. A running process's files are never
/// touched: a farm runs tracking chunks and render jobs in one folder at
/// once. Returns the names removed. Files of other names are never touched.
std::vector<std::string> remove_stale_temporaries(const std::string& dir, const std::vector<std::string>& stem_patterns,
                                                  std::chrono::seconds foreign_age = std::chrono::hours(1));

}  // namespace lapflow
