// EXR camera frames and depth (core/io.h readExr through OpenEXR, previz's channel and
// attribute handling, the timeCode attribute), as the take model reads a frame
// (take/take.h readImage8: float linear -> 8-bit sRGB) and as a depth map (readDepthExr).
#include <cstdlib>

#include "core/io.h"
#include "fuzz/fuzz_common.h"
#include "take/take.h"

// OpenCV's image limits (2^30 pixels) let a few hundred bytes declare gigabytes of pixels, which
// previz then allocates as OpenCV would; the harness lowers them (as a user may, through the
// same variables) so that its inputs are judged on parsing, not on the machine's memory.
[[maybe_unused]] static const int kLimits = [] {
  ::setenv("OPENCV_IO_MAX_IMAGE_PIXELS", "4194304", 0);
  return 0;
}();

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  const previz::fuzz::TempPath file("frame.exr");
  previz::fuzz::writeBytes(file.path(), data, size);
  previz::fuzz::guarded([&] {
    std::string format, timecode;
    int bit_depth = 0;
    previz::take::readImage8(file.path(), &format, &bit_depth, &timecode);
  });
  previz::fuzz::guarded([&] { previz::readDepthExr(file.path()); });
  return 0;
}
