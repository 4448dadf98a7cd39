// The batch manifest (batch/manifest.h readManifest: JOBDIR/manifest.json), then what every verb
// derives from it: each shard's stage commands and output paths.
#include "batch/manifest.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath dir("job");
    previz::fuzz::writeBytes(dir.path() / "manifest.json", data, size);
    const previz::batch::Manifest manifest = previz::batch::readManifest(dir.path());
    manifest.frameCount();
    for (const auto& shard : manifest.shards) {
      if (shard.take < 0 || shard.take >= static_cast<int>(manifest.takes.size())) continue;
      const auto& take = manifest.takes[shard.take];
      for (const auto& stage : take.stages) {
        manifest.command(shard, stage);
        for (int frame : shard.frames) manifest.outputs(take, stage, frame);
      }
    }
  });
}
