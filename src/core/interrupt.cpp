// SIGINT / SIGTERM: a flag for the frame loop, and on a second signal an
// immediate exit that first unlinks the temporary files being written. The
// handler uses only lock-free atomics, unlink(), write() and _exit(), all
// async-signal-safe.
#include "lapflow/core/interrupt.hpp"

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <climits>
#include <cstring>

namespace lapflow {
namespace {

static_assert(std::atomic<int>::is_always_lock_free, "the signal handler needs lock-free atomics");

// A frame writes at most six files, two frames may be in flight, plus the
// stats and manifest files: 64 slots leave room for embedding programs.
constexpr int kSlots = 64;
constexpr std::size_t kPathBytes = 4096;
enum SlotState : int { kFree = 0, kFilling = 1, kLive = 2 };

struct Slot {
  std::atomic<int> state{kFree};
  char path[kPathBytes];
};

Slot g_slots[kSlots];
std::atomic<int> g_stop{0};
std::atomic<int> g_last_frame{INT_MIN};  // INT_MIN: no frame complete yet
struct sigaction g_previous_int, g_previous_term, g_previous_xfsz;
bool g_installed = false;

void say(const char* text) {
  ssize_t ignored = ::write(STDERR_FILENO, text, std::strlen(text));
  (void)ignored;  // nothing to do about a failed message on the way out
}

void say_int(int v) {
  char digits[16];
  int n = 0;
  const bool negative = v < 0;
  unsigned u = negative ? 0u - unsigned(v) : unsigned(v);
  do digits[n++] = char('0' + u % 10); while ((u /= 10) && n < 15);
  char text[18];
  int k = 0;
  if (negative) text[k++] = '-';
  while (n > 0) text[k++] = digits[--n];
  text[k] = '\0';
  say(text);
}

const char* signal_name(int sig) { return sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "signal"; }

extern "C" void on_stop_signal(int sig) {
  const int saved_errno = errno;
  int none = 0;
  if (g_stop.compare_exchange_strong(none, sig)) {
    say("\nlapflow: ");
    say(signal_name(sig));
    say(": stopping after the frame in hand (send it again to stop at once)\n");
    errno = saved_errno;
    return;
  }
  // Second signal: no half file may stay behind, under any name.
  for (Slot& s : g_slots)
    if (s.state.load(std::memory_order_acquire) == kLive) ::unlink(s.path);
  say("\nlapflow: ");
  say(signal_name(sig));
  say(" again: stopped at once, temporary files removed; ");
  const int last = g_last_frame.load();
  if (last == INT_MIN) {
    say("no frame is complete\n");
  } else {
    say("the last complete frame is ");
    say_int(last);
    say("\n");
  }
  ::_exit(128 + sig);
}

}  // namespace

void install_stop_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;  // the loop polls the flag; blocking calls just go on
  struct sigaction ignore {};
  ignore.sa_handler = SIG_IGN;
  sigemptyset(&ignore.sa_mask);
  if (g_installed) return;
  sigaction(SIGINT, &sa, &g_previous_int);
  sigaction(SIGTERM, &sa, &g_previous_term);
  sigaction(SIGXFSZ, &ignore, &g_previous_xfsz);
  g_installed = true;
}

void restore_stop_handlers() {
  if (!g_installed) return;
  sigaction(SIGINT, &g_previous_int, nullptr);
  sigaction(SIGTERM, &g_previous_term, nullptr);
  sigaction(SIGXFSZ, &g_previous_xfsz, nullptr);
  g_installed = false;
}

int stop_signal() { return g_stop.load(); }

void request_stop(int signal) { g_stop.store(signal); }

void note_complete_frame(int frame) { g_last_frame.store(frame); }

TempFileRecord::TempFileRecord(const std::string& path) {
  if (path.size() >= kPathBytes) return;
  for (int i = 0; i < kSlots; ++i) {
    int expected = kFree;
    if (!g_slots[i].state.compare_exchange_strong(expected, kFilling)) continue;
    std::memcpy(g_slots[i].path, path.c_str(), path.size() + 1);
    g_slots[i].state.store(kLive, std::memory_order_release);
    slot_ = i;
    return;
  }
}

TempFileRecord::~TempFileRecord() {
  if (slot_ >= 0) g_slots[slot_].state.store(kFree, std::memory_order_release);
}

}  // namespace lapflow
