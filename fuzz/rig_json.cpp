// rig.json (core/rig.h readRig): cameras, intrinsics, distortion, extrinsics, roles.
#include "core/rig.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("rig.json");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::readRig(file.path()).validate();
  });
}
