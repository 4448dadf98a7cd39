// COLMAP text models (core/rig_import.h importColmap): the input is cameras.txt, then a line
// "=== images.txt" and images.txt (fuzz_common.h writeSplit).
#include "core/rig_import.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath dir("colmap");
    previz::fuzz::writeSplit(dir.path(), "cameras.txt", previz::fuzz::asString(data, size));
    previz::importColmap(dir.path(), previz::ImportOptions{});
  });
}
