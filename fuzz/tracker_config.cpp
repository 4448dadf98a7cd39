// Camera-tracker configuration (live/tracker.h readTrackerConfig: tracker.json).
#include "fuzz/fuzz_common.h"
#include "live/tracker.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("tracker.json");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::live::readTrackerConfig(file.path()).validate();
  });
}
