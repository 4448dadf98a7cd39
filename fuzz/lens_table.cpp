// Lens tables (calib/lens_table.h): previz's own lens/<lens>.json, then a lookup at a few lens
// states (the interpolation reads what the file gave).
#include "calib/lens_table.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("lens.json");
    previz::fuzz::writeBytes(file.path(), data, size);
    const previz::calib::LensTable table = previz::calib::readLensTable(file.path());
    for (double f : {0.0, 0.5, 1.0}) table.at(f, f);
  });
}
