// Other tools' camera rows (core/rig_import.h): Middlebury "name K R t" rows and 3x4 P rows, the
// same bytes through both readers.
#include "core/rig_import.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  const previz::fuzz::TempPath file("cameras.txt");
  previz::fuzz::writeBytes(file.path(), data, size);
  previz::ImportOptions options;
  options.width = 640;
  options.height = 480;
  previz::fuzz::guarded([&] { previz::importKRtRows(file.path(), options); });
  previz::fuzz::guarded([&] { previz::importProjectionRows(file.path(), options); });
  return 0;
}
