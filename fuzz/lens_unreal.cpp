// Unreal Engine lens files (.ulens, calib/lens_table.h readUnrealLensFile), then a lookup.
#include "calib/lens_table.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("lens.ulens");
    previz::fuzz::writeBytes(file.path(), data, size);
    const previz::calib::LensTable table = previz::calib::readUnrealLensFile(file.path());
    for (double f : {0.0, 0.5, 1.0}) table.at(f, f);
  });
}
