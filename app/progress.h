#pragma once
// A progress line for long CLI jobs: frames done, fps, ETA on stderr. On a terminal it rewrites
// one line; otherwise (logs, CI) it prints a line at most every few seconds.
#include <cstdio>
#include <string>

#include <unistd.h>

#include "core/stopwatch.h"

namespace previz::app {

class ProgressLine {
 public:
  ProgressLine(std::string label, int total, bool quiet = false)
      : label_(std::move(label)), total_(total), quiet_(quiet), tty_(isatty(2) != 0) {}

  void update(int done) {
    if (quiet_) return;
    const double elapsed = since_start_.seconds();
    if (!tty_ && done < total_ && since_print_.seconds() < 5.0) return;
    since_print_.restart();
    const double fps = elapsed > 0 ? done / elapsed : 0.0;
    const double eta = fps > 0 ? (total_ - done) / fps : 0.0;
    std::fprintf(stderr, "%s[%s] frame %d/%d | %.2f fps | elapsed %.1f s | ETA %.1f s%s",
                 tty_ ? "\r" : "", label_.c_str(), done, total_, fps, elapsed, eta,
                 tty_ ? "   " : "\n");
    if (tty_ && done >= total_) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }

 private:
  std::string label_;
  int total_;
  bool quiet_;
  bool tty_;
  Stopwatch since_start_, since_print_;
};

}  // namespace previz::app
