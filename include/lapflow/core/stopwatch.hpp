#pragma once
/// \file stopwatch.hpp Wall-clock timing of the stages, in one place.
#include <chrono>

namespace lapflow {

/// Measures wall seconds from its creation or its last lap.
class Stopwatch {
 public:
  /// Seconds since the start or the previous lap(); starts the next lap.
  double lap() {
    const Clock::time_point now = Clock::now();
    const double s = std::chrono::duration<double>(now - lap_start_).count();
    lap_start_ = now;
    return s;
  }
  /// Seconds since the stopwatch was created (laps do not reset it).
  double total() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point start_ = Clock::now(), lap_start_ = start_;
};

}  // namespace lapflow
