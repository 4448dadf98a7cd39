#pragma once
// Elapsed wall time with one spelling across previz (issue 34): started when made, read as often
// as wanted, restarted for the next interval. steady_clock: never goes back when the system clock
// is set. For deadlines and schedules keep std::chrono time points; this only measures.
#include <chrono>

namespace previz {

class Stopwatch {
 public:
  Stopwatch() : start_(Clock::now()) {}

  double ms() const { return std::chrono::duration<double, std::milli>(Clock::now() - start_).count(); }
  double seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }
  void restart() { start_ = Clock::now(); }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point start_;
};

}  // namespace previz
