// Nuke / Maya .chan files (batch/chan.h readChan: frame tx ty tz rx ry rz per line), then the
// poses they give.
#include "batch/chan.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("camera.chan");
    previz::fuzz::writeBytes(file.path(), data, size);
    for (const previz::batch::ChanKey& key : previz::batch::readChan(file.path())) key.pose();
  });
}
