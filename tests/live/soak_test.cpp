// live/soak.h: a short soak (200 frames of a small synthetic studio, every fault kind twice)
// accounted exactly: each injected fault found in the report as the loop must handle it, every
// report explained by a fault, frames in = processed + failed, the output ring complete.
// Wall-clock figures are reported, never asserted. About 10 s on 2 cores.
#include <gtest/gtest.h>

#include <map>
#include <set>

#include "core/io.h"
#include "datasets/synth.h"
#include "live/soak.h"
#include "tests/scratch.h"

namespace previz::live {
namespace {

namespace fs = std::filesystem;

TEST(Soak, EveryFaultMatchedToItsHandlingAndEveryFrameAccountedFor) {
  const fs::path dir = test::scratchDir("live", "soak");
  synth::SynthOptions so;
  so.frames = 12;
  so.witness_cameras = 4;
  so.witness_width = 160;
  so.witness_height = 96;
  so.main_width = 240;
  so.main_height = 136;
  so.noise_sigma = 2;
  so.write_meshes = false;
  synth::synthesizeTake(so, dir / "take");

  SoakOptions o;
  o.take = dir / "take";
  o.out = dir / "soak";
  o.frames = 200;
  o.period = 100;
  o.warmup_frames = 40;
  o.rss_window = 40;
  o.output_slots = 16;
  o.loop.threads = 2;
  const SoakReport r = runSoak(o);
  SCOPED_TRACE(r.fullReport());

  // Every kind injected twice (two periods), each handled as it must be.
  const std::set<std::string> kinds = {"witness_unplugged", "witness_corrupt", "witness_truncated", "main_corrupt",
                                       "main_truncated",    "camera_late",     "tracker_loss",      "tracker_reorder",
                                       "tracker_outage",    "disk_full"};
  std::map<std::string, int> injected;
  for (const SoakFault& f : r.faults) {
    ++injected[f.kind];
    EXPECT_TRUE(f.matched) << f.kind << " at frames " << f.first_frame << ".." << f.end_frame << ": " << f.observed;
  }
  for (const std::string& k : kinds) EXPECT_EQ(injected[k], 2) << k;
  EXPECT_EQ(injected.size(), kinds.size());
  EXPECT_TRUE(r.unexplained.empty());

  // Frames: none silently dropped. The failures are exactly the main plates damaged and the
  // frames the tracker outages leave without a pose, each with its reason.
  EXPECT_EQ(r.frames_in, 200);
  EXPECT_EQ(r.frames_processed + r.frames_failed, r.frames_in);
  EXPECT_EQ(static_cast<int>(r.failed.size()), r.frames_failed);
  int main_damaged = 0, no_pose = 0;
  for (const SoakEvent& e : r.failed) {
    ASSERT_FALSE(e.reason.empty());
    if (e.reason.find("main plate unusable") != std::string::npos) ++main_damaged;
    else if (e.reason.find("no tracker pose") != std::string::npos) ++no_pose;
    else ADD_FAILURE() << "frame " << e.frame << " failed for no injected reason: " << e.reason;
  }
  EXPECT_EQ(main_damaged, 4);
  EXPECT_GT(no_pose, 0);
  EXPECT_EQ(no_pose, r.tracker.frames_without_pose);
  EXPECT_EQ(r.tracker.frames_posed + r.tracker.frames_without_pose, r.frames_in - main_damaged);

  // Camera drops: the unplugged, damaged and late witnesses' frames, nothing else. Span of an
  // unplug / late window at period 100: max(3, 100 / 25) = 4 frames.
  EXPECT_EQ(r.dropped.size(), 2u * (4 + 1 + 1 + 4));
  // Tracker: 2 lost (loss) + 30 lost (outage) + 1 gap of a swapped pair, per period.
  EXPECT_EQ(r.tracker.missing, 2 * (2 + 30 + 1));
  EXPECT_EQ(r.tracker.out_of_order, 2);
  // Disk full: both files of each of its 4 frames skipped, per period; nothing half-written.
  EXPECT_EQ(r.skipped_writes.size(), 2u * 4 * 2);
  for (const SoakEvent& e : r.skipped_writes) EXPECT_NE(e.reason.find("No space left on device"), std::string::npos);
  EXPECT_EQ(r.output_files, 2 * o.output_slots);
  EXPECT_EQ(r.outputs_complete, r.output_files);
  EXPECT_TRUE(r.output_problems.empty());

  // The report on disk says the same; RSS and frame times are there (not asserted: timing).
  const nlohmann::json j = readJsonFile(o.out / "soak.json");
  EXPECT_EQ(j["frames"]["in"], 200);
  EXPECT_EQ(j["frames"]["processed"], r.frames_processed);
  EXPECT_EQ(j["series"]["rss_mib"].size(), 200u);
  EXPECT_GT(r.rss_start_mib, 0);
  EXPECT_TRUE(fs::file_size(o.out / "soak.svg") > 0);
  // The input take is never modified: the faults act on the working copy.
  EXPECT_FALSE(fs::exists(o.out / "take" / "truth"));
}

}  // namespace
}  // namespace previz::live
