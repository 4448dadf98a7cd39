// Kalibr target YAML (core/board.h readBoard on a .yaml: aprilgrid / checkerboard / circlegrid),
// through previz's Kalibr YAML subset parser (core/detail/yaml_subset.h).
#include "core/board.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("target.yaml");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::readBoard(file.path());
  });
}
