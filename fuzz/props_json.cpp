// props.json (tracking/props.h readProps): props as rigid sets of tags (family, ids, size, corners).
#include "fuzz/fuzz_common.h"
#include "tracking/props.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("props.json");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::tracking::readProps(file.path());
  });
}
