#pragma once
// CPU time, ms, for figures that must hold on a machine shared with other work: the process's
// (every thread: what a stage cost in all) or the calling thread's (one item of a parallel loop).
// Wall time is core/stopwatch.h's.
#include <time.h>

namespace previz {

inline double cpuClockMs(clockid_t clock) {
  timespec t{};
  clock_gettime(clock, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}
inline double processCpuMs() { return cpuClockMs(CLOCK_PROCESS_CPUTIME_ID); }
inline double threadCpuMs() { return cpuClockMs(CLOCK_THREAD_CPUTIME_ID); }

}  // namespace previz
