// Frame-sync check: a camera whose frames lag the others is named with its offset; a rig in
// sync is left alone. Observation-level data from the true studio rig (exact projections of
// the rig preset's board path plus pixel noise), and image-level detections from the capture
// fixture.
#include "multicam/sync.h"
#include "multicam/pipeline.h"

#include <gtest/gtest.h>

#include <filesystem>

#include "core/error.h"
#include "datasets/random.h"
#include "datasets/rigs.h"
#include "datasets/scene.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

// Observations of the rig preset's board by the true studio rig: camera c's frame f sees the
// board of frame f - delay(c) (clamped at 0), pixels with Gaussian noise sigma_px.
RigObservations simulate(const Rig& rig, const BoardSpec& board, int frames,
                         const std::map<std::string, int>& delay, double sigma_px) {
  RigObservations obs;
  obs.board = board;
  obs.frame_count = frames;
  obs.has_floor = true;
  obs.floor.board = board;
  obs.floor.T_world_board = synth::floorBoardPose();
  for (int f = 0; f < frames; ++f) {
    if (synth::isFloorBoardFrame(f, frames)) obs.floor.frames.push_back(f);
  }
  const synth::Scene empty;  // the board is flat: nothing else occludes it in the rig preset
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    const RigCamera& rc = rig.cameras[c];
    CameraDetections d;
    d.camera = rc.camera.name;
    d.image_size = cv::Size(rc.camera.width, rc.camera.height);
    const auto it = delay.find(d.camera);
    const int lag = it == delay.end() ? 0 : it->second;
    for (int f = 0; f < frames; ++f) {
      const int shown = std::max(0, f - lag);
      const Pose T_world_board = synth::rigBoardPose(board, shown, frames, 1);
      std::vector<calib::Observation> points;
      for (const synth::BoardObservation& b :
           synth::visibleBoardPoints(rc.camera, rc.T_world_cam, board, T_world_board, empty)) {
        const std::uint64_t key = synth::hashKey(7, c, f, static_cast<std::uint64_t>(b.id));
        calib::Observation o;
        o.id = b.id;
        o.px = b.px + sigma_px * Eigen::Vector2d(synth::normalFromKey(key), synth::normalFromKey(key + 1));
        points.push_back(o);
      }
      if (points.size() >= 6) d.frames[f] = points;
    }
    obs.cameras.push_back(d);
  }
  return obs;
}

Rig studio() {
  synth::StudioRigOptions o;  // 8 witnesses 1280x720 + main 1920x1080
  return synth::studioRig(o, 10.0, false);
}

const CameraSync& find(const SyncReport& r, const std::string& name) {
  for (const CameraSync& c : r.cameras) {
    if (c.camera == name) return c;
  }
  throw std::runtime_error("no camera " + name);
}

TEST(Sync, CameraDelayedTwoFramesIsNamedWithItsOffset) {
  const Rig rig = studio();
  const BoardSpec board = synth::rigBoard(BoardType::kAprilGrid);
  const RigObservations obs = simulate(rig, board, 150, {{"witness03", 2}}, 0.3);
  const SyncReport r = checkSync(obs, rig);
  ASSERT_EQ(r.cameras.size(), rig.cameras.size());
  EXPECT_FALSE(r.ok);
  for (const CameraSync& c : r.cameras) {
    SCOPED_TRACE(c.camera);
    EXPECT_GT(c.pairs, 0);
    EXPECT_EQ(c.offset_frames, c.camera == "witness03" ? 2 : 0);
    EXPECT_EQ(c.in_sync, c.camera != "witness03");
  }
  const CameraSync& late = find(r, "witness03");
  // The right offset explains the relative pose far better than none.
  EXPECT_LT(late.spread_at_offset, 0.25 * late.spread_at_zero);
  EXPECT_TRUE(r.unchecked.empty());
}

// The rig chain as one call (multicam/pipeline.h, what `previz rig calibrate` and the demo run):
// the solve from the intrinsics, then the sync check against the solved rig, a late camera named.
TEST(Sync, RigPipelineSolvesThenNamesTheLateCamera) {
  const Rig rig = studio();
  const BoardSpec board = synth::rigBoard(BoardType::kAprilGrid);
  Rig initial = rig;
  for (RigCamera& rc : initial.cameras) rc.T_world_cam = Pose::Identity();  // intrinsics only
  const RigPipelineResult in_sync = solveRigTake(simulate(rig, board, 150, {}, 0.3), initial);
  EXPECT_TRUE(in_sync.sync.ok);
  EXPECT_TRUE(in_sync.calib.world_from_floor);
  for (const RigCamera& rc : in_sync.calib.rig.cameras)
    EXPECT_LT((rc.T_world_cam.translation() - rig.at(rc.camera.name).T_world_cam.translation()).norm(), 0.005)
        << rc.camera.name;
  const RigPipelineResult late = solveRigTake(simulate(rig, board, 150, {{"witness03", 2}}, 0.3), initial);
  EXPECT_FALSE(late.sync.ok);
  EXPECT_EQ(find(late.sync, "witness03").offset_frames, 2);
  EXPECT_FALSE(find(late.sync, "witness03").in_sync);
  RigPipelineOptions bad;
  bad.sync.max_offset = -1;
  EXPECT_THROW(solveRigTake(simulate(rig, board, 20, {}, 0.3), initial, bad), Error);
}

TEST(Sync, CameraAheadOneFrameGetsNegativeOffset) {
  const Rig rig = studio();
  const BoardSpec board = synth::rigBoard(BoardType::kAprilGrid);
  // Everyone but witness05 lags by one frame: witness05 is one frame ahead of the majority.
  std::map<std::string, int> delay;
  for (const std::string& name : rig.names()) {
    if (name != "witness05") delay[name] = 1;
  }
  const SyncReport r = checkSync(simulate(rig, board, 150, delay, 0.3), rig);
  EXPECT_FALSE(r.ok);
  for (const CameraSync& c : r.cameras) {
    SCOPED_TRACE(c.camera);
    EXPECT_EQ(c.offset_frames, c.camera == "witness05" ? -1 : 0);
  }
}

TEST(Sync, RigInSyncHasEveryOffsetZero) {
  const Rig rig = studio();
  const BoardSpec board = synth::rigBoard(BoardType::kAprilGrid);
  const SyncReport r = checkSync(simulate(rig, board, 150, {}, 0.3), rig);
  EXPECT_TRUE(r.ok);
  EXPECT_TRUE(r.unchecked.empty());
  for (const CameraSync& c : r.cameras) {
    SCOPED_TRACE(c.camera);
    EXPECT_EQ(c.offset_frames, 0);
    EXPECT_TRUE(c.in_sync);
    EXPECT_GT(c.pairs, 0);
    // Pose consistency of noisy PnP at 4-6 m: centimetres, not decimetres.
    EXPECT_LT(c.spread_at_offset, 0.1);
  }
  for (const PairSync& p : r.pairs) {
    if (p.decisive) {
      EXPECT_EQ(p.best_offset, 0) << p.a << "-" << p.b;
    }
  }
}

TEST(Sync, CameraWithoutDetectionsIsUncheckedNotFailed) {
  Rig rig = studio();
  const BoardSpec board = synth::rigBoard(BoardType::kAprilGrid);
  RigObservations obs = simulate(rig, board, 80, {}, 0.3);
  obs.cameras.erase(obs.cameras.begin() + 1);  // witness02 has no detections at all
  const SyncReport r = checkSync(obs, rig);
  EXPECT_TRUE(r.ok);
  ASSERT_EQ(r.unchecked.size(), 1u);
  EXPECT_EQ(r.unchecked[0], "witness02");
}

TEST(Sync, BadOptionsNameTheField) {
  SyncOptions o;
  o.max_offset = -1;
  try {
    o.validate();
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "max_offset");
  }
}

// Image-level: detections of a rendered capture with witness03 two frames late, written by the
// multicam.capture fixture (a CTest fixture this test requires), so the file must be there.
TEST(Sync, RenderedCaptureWithDelayedWitnessIsNamed) {
  const fs::path dir = PREVIZ_MULTICAM_CAPTURE;
  const fs::path file = dir / "delayed_witness03.json";
  ASSERT_TRUE(fs::exists(file)) << file << " missing: the multicam.capture fixture did not write it";
  ASSERT_TRUE(fs::exists(dir / "truth_rig.json")) << "truth_rig.json missing in " << dir;
  const RigObservations obs = readObservations(file);
  const Rig truth = readRig(dir / "truth_rig.json");
  const SyncReport r = checkSync(obs, truth);
  EXPECT_FALSE(r.ok);
  for (const CameraSync& c : r.cameras) {
    if (!obs.find(c.camera)) continue;
    SCOPED_TRACE(c.camera);
    EXPECT_EQ(c.offset_frames, c.camera == "witness03" ? 2 : 0);
  }
  const CameraSync& late = find(r, "witness03");
  EXPECT_GE(late.pairs, 3);
  EXPECT_LT(late.spread_at_offset, 0.25 * late.spread_at_zero);
  // 100 frames: a camera may share too few with the others to be told, not more than one.
  EXPECT_LE(r.unchecked.size(), 1u);
}

}  // namespace
}  // namespace previz::multicam
