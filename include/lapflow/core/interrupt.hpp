#pragma once
/// \file interrupt.hpp Stopping a long run cleanly on SIGINT / SIGTERM.
///
/// A signal handler can do almost nothing safely, so this is the one piece of
/// process-wide state in lapflow: a stop flag that the frame loop reads
/// between steps, and a fixed table of the temporary files being written,
/// which the handler unlinks itself when a second signal asks to stop at
/// once. Both work without handlers too: a program embedding the library can
/// call request_stop(), and the temporary-file table is then simply unused.
#include <string>

namespace lapflow {

/// Installs the handlers of SIGINT and SIGTERM (also when the parent left
/// SIGINT ignored, as a shell does for a background job: a bake should stop
/// when asked) and ignores SIGXFSZ, so a file-size limit makes write() fail
/// with EFBIG (an error naming the file) instead of killing the process.
/// First signal: stop_signal() returns it; the caller finishes or abandons
/// the frame in hand. Second signal: the handler unlinks every registered
/// temporary file, prints the last complete frame and calls _exit(128 + sig).
void install_stop_handlers();

/// Puts back the handlers install_stop_handlers() replaced (a command that
/// goes on with other work after its bake, such as `lapflow demo`).
void restore_stop_handlers();

/// The signal that asked the process to stop (SIGINT, SIGTERM), or 0.
int stop_signal();

/// Asks for a stop as the first signal `signal` would (0 clears the request):
/// for tests and programs that embed the library.
void request_stop(int signal);

/// The last frame whose files are all in place, for the message of a hard
/// stop (a second signal). Call after each frame's files are committed.
void note_complete_frame(int frame);

/// Registers a temporary file about to be created, for the handler to unlink
/// on a hard stop; unregisters on destruction (after the file was renamed or
/// removed). Registration never fails: when the fixed table is full, the file
/// is simply not unlinked by the handler (the next bake's start removes it).
class TempFileRecord {
 public:
  explicit TempFileRecord(const std::string& path);
  ~TempFileRecord();
  TempFileRecord(const TempFileRecord&) = delete;
  TempFileRecord& operator=(const TempFileRecord&) = delete;

 private:
  int slot_ = -1;
};

}  // namespace lapflow
