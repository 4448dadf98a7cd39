// The take model's small parsers (take/sequence.h, take/timecode.h): a sequence pattern given by
// a user ("A001C003.%04d.exr", "####"), file names matched against it, SMPTE timecodes from
// containers and EXR headers and their frame counts at the usual rates.
#include <string>

#include "fuzz/fuzz_common.h"
#include "take/sequence.h"
#include "take/timecode.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  const std::string text = previz::fuzz::asString(data, size);
  previz::fuzz::guarded([&] {
    if (const auto pattern = previz::take::parsePattern(text)) {
      pattern->str();
      pattern->frameOf(text);
      for (long long frame : {0LL, 1001LL, -1LL}) pattern->frameOf(pattern->fileName(frame));
    }
  });
  previz::fuzz::guarded([&] {
    if (const auto tc = previz::take::parseTimecode(text)) {
      previz::take::formatTimecode(*tc);
      for (double fps : {24.0, 25.0, 29.97, 30.0, 59.94, 120.0}) {
        previz::fuzz::guarded([&] {
          const long long frames = previz::take::timecodeToFrames(*tc, fps);
          previz::take::framesToTimecode(frames, fps, tc->drop_frame);
        });
      }
    }
  });
  return 0;
}
