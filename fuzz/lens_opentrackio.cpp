// OpenTrackIO lens samples (calib/lens_table.h readOpenTrackIoLens), then a lookup.
#include "calib/lens_table.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("lens_opentrackio.json");
    previz::fuzz::writeBytes(file.path(), data, size);
    const previz::calib::LensTable table = previz::calib::readOpenTrackIoLens(file.path());
    for (double f : {0.0, 0.5, 1.0}) table.at(f, f);
  });
}
