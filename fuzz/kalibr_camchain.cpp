// Kalibr camchain.yaml (core/rig_import.h importKalibr), through previz's Kalibr YAML subset
// parser (core/detail/yaml_subset.h).
#include "core/rig_import.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("camchain.yaml");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::importKalibr(file.path(), previz::ImportOptions{});
  });
}
