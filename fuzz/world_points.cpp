// Surveyed world points (core/rig_world.h readWorldPoints: {"points": [{"name", "world",
// "rig"}], "fit_scale"}), as `previz camera import --world-points` reads them.
#include "core/rig_world.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("points.json");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::readWorldPoints(file.path());
  });
}
