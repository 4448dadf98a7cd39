// The batch plan (batch/manifest.h): shards cover every frame once; a changed input is refused
// naming the file (issue 9, item 3); the ledger sends a damaged frame, and only it, back to carve.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "batch/backend.h"
#include "batch/ledger.h"
#include "batch/manifest.h"
#include "batch_fixture.h"
#include "core/error.h"
#include "core/io.h"
#include "core/rig.h"
#include "scratch.h"

namespace previz::batch {
namespace {
namespace fs = std::filesystem;

PlanOptions planFor(const test::BatchFixture& f, const fs::path& rig, const fs::path& out) {
  PlanOptions o;
  o.takes = {f.take};
  o.rig = rig;
  o.out = out;
  o.previz = PREVIZ_BIN;
  return o;
}

TEST(BatchManifest, ShardsCoverEveryFrameOnceAndCommandsCarryTheShard) {
  const test::BatchFixture& f = test::batchFixture();
  PlanOptions o = planFor(f, f.take / "truth" / "rig.json", test::scratchDir("batch", "plan") / "job");
  o.shards_per_take = 3;
  const Manifest m = planBatch(o);
  ASSERT_EQ(m.shards.size(), 3u);
  std::multiset<int> seen;
  for (const ShardPlan& s : m.shards) {
    seen.insert(s.frames.begin(), s.frames.end());
    const std::vector<std::string> argv = m.command(s, m.takes[0].stages[0]);
    EXPECT_NE(std::find(argv.begin(), argv.end(), std::to_string(s.index) + "/3"), argv.end());
  }
  EXPECT_EQ(seen, std::multiset<int>({0, 1, 2, 3}));
  // The manifest's hash does not depend on the job folder (commands keep {job}), so two job
  // folders of the same batch can be compared.
  PlanOptions other = o;
  other.out = o.out.parent_path() / "elsewhere";
  EXPECT_EQ(planBatch(other).hash, m.hash);
  // A setting changes it.
  other.voxel_m = 0.03;
  EXPECT_NE(planBatch(other).hash, m.hash);
  // Written and read back.
  writeManifest(m);
  const Manifest back = readManifest(o.out);
  EXPECT_EQ(back.hash, m.hash);
  EXPECT_EQ(back.shards.size(), 3u);
  EXPECT_EQ(back.shards[2].frames, m.shards[2].frames);
  EXPECT_EQ(arrayList({7, 0, 1, 2, 5, 8}), "0-2,5,7-8");

  // Depth cameras: all but the main camera by default, a list as given, and an unknown one is
  // refused, named.
  EXPECT_EQ(m.takes[0].depth_cameras,
            (std::vector<std::string>{"witness01", "witness02", "witness03", "witness04"}));
  PlanOptions listed = o;
  listed.depth_cameras = "witness03,main";
  const Manifest l = planBatch(listed);
  EXPECT_EQ(l.takes[0].depth_cameras, std::vector<std::string>{"witness03"});
  const std::vector<std::string>& argv = l.takes[0].stages[0].command;
  const auto it = std::find(argv.begin(), argv.end(), "--depth-cameras");
  ASSERT_NE(it, argv.end());
  EXPECT_EQ(*(it + 1), "witness03");
  PlanOptions none = o;
  none.depth_cameras = "main";
  EXPECT_TRUE(planBatch(none).takes[0].depth_cameras.empty());
  PlanOptions unknown = o;
  unknown.depth_cameras = "witness09";
  try {
    planBatch(unknown);
    ADD_FAILURE() << "an unknown depth camera was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("witness09"), std::string::npos) << e.what();
    EXPECT_EQ(e.context().field, "--depth-cameras");
  }
}

TEST(BatchManifest, ChangedRigBetweenPlanAndResumeIsRefusedNamingTheFile) {
  const test::BatchFixture& f = test::batchFixture();
  const fs::path dir = test::scratchDir("batch", "rigchange");
  const fs::path rig = dir / "rig.json";
  fs::copy_file(f.take / "truth" / "rig.json", rig);
  const Manifest m = planBatch(planFor(f, rig, dir / "job"));
  writeManifest(m);
  EXPECT_NO_THROW(requireUnchangedInputs(m));
  // A re-surveyed witness: 2 mm to the side.
  Rig r = readRig(rig);
  r.cameras[0].T_world_cam.translation().x() += 0.002;
  writeRig(r, rig);
  try {
    requireUnchangedInputs(readManifest(dir / "job"));
    FAIL() << "a changed rig was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, rig.string());
    EXPECT_NE(std::string(e.what()).find("refusing to mix"), std::string::npos) << e.what();
  }
  // The CLI says the same, and exits non-zero, for resume and for the task a scheduler runs.
  std::string out;
  EXPECT_NE(test::shell(test::quoted(PREVIZ_BIN) + " batch resume " + test::quoted(dir / "job") + " --local", &out), 0);
  EXPECT_NE(out.find(rig.string()), std::string::npos) << out;
  EXPECT_NE(test::shell(test::quoted(PREVIZ_BIN) + " batch task " + test::quoted(dir / "job") + " --shard 0", &out), 0);
  EXPECT_NE(out.find(rig.string()), std::string::npos) << out;
  // Planning again into the same folder is refused too, unless --force.
  EXPECT_NE(test::shell(test::quoted(PREVIZ_BIN) + " batch plan --takes " + test::quoted(f.take) + " --rig " +
                            test::quoted(rig) + " --out " + test::quoted(dir / "job"), &out), 0);
  EXPECT_NE(out.find("rig.json"), std::string::npos) << out;
  EXPECT_EQ(test::shell(test::quoted(PREVIZ_BIN) + " batch plan --takes " + test::quoted(f.take) + " --rig " +
                            test::quoted(rig) + " --out " + test::quoted(dir / "job") + " --force", &out), 0) << out;
  EXPECT_NO_THROW(requireUnchangedInputs(readManifest(dir / "job")));
}

// Every frame output's last write time, keyed by path relative to the job.
std::map<std::string, fs::file_time_type> frameFileTimes(const fs::path& job) {
  std::map<std::string, fs::file_time_type> times;
  for (const auto& e : fs::recursive_directory_iterator(job / "work")) {
    if (!e.is_regular_file() || e.path().filename() == "carve.jsonl") continue;
    times[fs::relative(e.path(), job).string()] = e.last_write_time();
  }
  return times;
}

TEST(BatchLedger, DamagedFrameIsRedoneLocallyAndNothingElseIsRewritten) {
  const test::BatchFixture& f = test::batchFixture();
  const fs::path job = test::scratchDir("batch", "ledger") / "job";
  fs::copy(f.job, job, fs::copy_options::recursive);
  const Manifest m = readManifest(job);
  for (const ShardPlan& s : m.shards) ASSERT_TRUE(checkShard(m, s.id).complete()) << "shard " << s.id;

  // Damage one byte of frame 1's OBJ (same size: only the checksum can tell).
  const fs::path obj = job / "work" / "take" / "carve" / "mesh" / "000001.obj";
  const std::string original = readTextFile(obj);
  std::string damaged = original;
  damaged[damaged.size() / 2] = damaged[damaged.size() / 2] == '7' ? '8' : '7';
  writeFileAtomic(obj, damaged);
  const int shard = m.shards[0].frames == std::vector<int>{0, 2} ? 1 : 0;
  const ShardCheck check = checkShard(m, shard);
  ASSERT_EQ(check.bad.size(), 1u);
  EXPECT_EQ(check.bad[0].first, 1);
  EXPECT_NE(check.bad[0].second.find("checksum"), std::string::npos) << check.bad[0].second;
  EXPECT_EQ(check.state(), "corrupt");

  const auto before = frameFileTimes(job);
  std::string out;
  ASSERT_EQ(test::shell(test::quoted(PREVIZ_BIN) + " batch resume " + test::quoted(job) + " --local --jobs 2 --json", &out), 0) << out;
  EXPECT_NE(out.find("\"shards\":[" + std::to_string(shard) + "]"), std::string::npos) << out;
  const auto after = frameFileTimes(job);
  ASSERT_EQ(after.size(), before.size());
  int rewritten = 0;
  for (const auto& [path, t] : after) {
    const bool frame1 = path.find("/000001.") != std::string::npos;
    if (frame1) {
      EXPECT_NE(t, before.at(path)) << path << " of the damaged frame was not redone";
      ++rewritten;
    } else {
      EXPECT_EQ(t, before.at(path)) << path << " was rewritten";
    }
  }
  // Depth exr + png of main and 4 witnesses, refined depth exr + png, mesh ply + obj, points ply
  // + pcd, report.
  EXPECT_EQ(rewritten, 17);
  EXPECT_EQ(readTextFile(obj), original) << "the redone OBJ equals the first run's";
  for (const ShardPlan& s : m.shards) EXPECT_TRUE(checkShard(m, s.id).complete()) << "shard " << s.id;
}

}  // namespace
}  // namespace previz::batch
