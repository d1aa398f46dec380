// The time a station process's timeouts go by: a scan given up when its captures stop, a
// product's missing chunks asked again, a page that waits for its point map, a light left on,
// a projector that hears no capture. A daemon runs on the steady clock; a node's test runs on
// a clock it steps, so that a 30 s timeout is tested at once, and a loaded machine that is slow
// to deliver a message never makes a timeout fire that the test did not ask for.
//
// Not on it: what is physical or the process's own health (the projector's settle after a
// frame, the pacing of chunks on the bus, the status heartbeat, the watchdog's stuck job),
// which keep the steady clock.
#pragma once

#include <atomic>
#include <chrono>

namespace vellum::station {

class Clock {
 public:
  using time_point = std::chrono::steady_clock::time_point;
  using duration = std::chrono::steady_clock::duration;

  virtual ~Clock() = default;
  virtual time_point Now() const = 0;

  // The steady clock (one, for the whole process).
  static const Clock& Steady();
};

// A clock that moves only when stepped (thread-safe: the LCM thread and the worker read it
// while the test steps it). It starts at the steady clock's present, so that no time it gives
// is the epoch a member's "never" is written as.
class SteppedClock final : public Clock {
 public:
  SteppedClock() : ticks_(std::chrono::steady_clock::now().time_since_epoch().count()) {}
  time_point Now() const override { return time_point(duration(ticks_.load())); }
  void Advance(double seconds) {
    ticks_ += std::chrono::duration_cast<duration>(std::chrono::duration<double>(seconds)).count();
  }

 private:
  std::atomic<duration::rep> ticks_;
};

namespace clock_detail {
class SteadyClock final : public Clock {
 public:
  time_point Now() const override { return std::chrono::steady_clock::now(); }
};
}  // namespace clock_detail

inline const Clock& Clock::Steady() {
  static const clock_detail::SteadyClock clock;
  return clock;
}

// Seconds as the clock's duration (a timeout option in seconds, compared with Now() - since).
inline Clock::duration Seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

}  // namespace vellum::station
