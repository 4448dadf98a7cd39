// Camera frames as previz's own codecs decode them (core/detail/image_codecs.h decodeImage: PNG
// through libpng, JPEG through libjpeg, with previz's EXIF orientation handling), unchanged and
// as colour, then the take model's conversion to 8-bit BGR (take/take.h toBgr8).
#include <cstdlib>

#include <opencv2/core.hpp>

#include "core/detail/image_codecs.h"
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
  const std::string bytes = previz::fuzz::asString(data, size);
  for (int flags : {-1 /* IMREAD_UNCHANGED */, 1 /* IMREAD_COLOR */, 0 /* IMREAD_GRAYSCALE */}) {
    previz::fuzz::guarded([&] {
      if (const auto image = previz::detail::decodeImage(bytes, flags))
        if (!image->empty()) previz::take::toBgr8(*image);
    });
  }
  return 0;
}
