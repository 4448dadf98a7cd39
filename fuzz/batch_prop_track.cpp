// Prop tracks (batch/collect.h readPropTrack): a "track" stage's JSON lines {"frame", "props":
// [{"id", "name", "T_world_prop", "state"}]} as `previz batch collect` reads them.
#include "batch/collect.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("poses.jsonl");
    previz::fuzz::writeBytes(file.path(), data, size);
    previz::batch::readPropTrack(file.path());
  });
}
