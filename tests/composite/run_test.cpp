// Issue 7 item 1 with the true cameras: the whole live frame (key -> carve -> main-view depth
// -> composite) on the studio take against its true composite.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "core/error.h"
#include "core/pose.h"
#include "core/rig.h"
#include "datasets/rigs.h"
#include "multicam/observations.h"
#include "multicam/rig_calib.h"
#include "tests/composite/take_fixture.h"

namespace previz::composite::test {
namespace {

TEST(RunTrueRig, CompositeMatchesTruthOverTheActorAndKeepsDepthOrder) {
  const fs::path& take = studioTake();
  const TakeMeasure m = measureTake(take, take / "truth" / "rig.json", "", "true rig and poses");
  ASSERT_EQ(m.frames.size(), 5u);
  // The take must exercise both orders: the actor behind the pillar at 2 s, in front at 8 s.
  EXPECT_GT(m.frames[1].truth_behind_px, 1000) << "actor not behind the CG at t = 2 s";
  EXPECT_LT(m.frames[4].truth_behind_px, m.frames[4].actor_px / 2) << "actor not in front at t = 8 s";
  EXPECT_GE(m.min_psnr_db, 30.0);
  EXPECT_LE(m.wrongFraction(), 0.005);
}

// Live preview with the witnesses keyed and carved at half resolution (FrameLoopOptions
// witness_bin = 2; `run --witness-bin 2`): the main camera's key, depth and composite against
// the truth as at full resolution, and beside the full-resolution loop on the same take.
TEST(RunTrueRig, WitnessesBinnedTwoByTwoKeepTheComposite) {
  const fs::path& take = studioTake();
  const fs::path rig = take / "truth" / "rig.json";
  const TakeMeasure full = measureTake(take, rig, "", "true rig, witnesses at full resolution");
  const TakeMeasure half = measureTake(take, rig, "", "true rig, witnesses binned 2 x 2", 2);
  ASSERT_EQ(half.frames.size(), full.frames.size());
  EXPECT_GE(half.min_psnr_db, 30.0);
  EXPECT_LE(half.wrongFraction(), 0.005);
  for (size_t i = 0; i < half.frames.size(); ++i)
    EXPECT_GE(half.frames[i].psnr_db, full.frames[i].psnr_db - 1.0) << "frame " << half.frames[i].frame;
  // The coarser silhouettes widen the hull: a little more depth error, not a different figure.
  EXPECT_LE(half.depthErrQuantile(0.5), full.depthErrQuantile(0.5) + 0.004);
  EXPECT_LE(half.depthErrQuantile(0.9), full.depthErrQuantile(0.9) + 0.010);
}

// A binned witness plate must come at its rig camera's size: one that does not (a camera set to
// another resolution) drops that camera for the frame with the sizes named, and the frame goes on.
TEST(FrameLoop, BinnedWitnessPlateOfTheWrongSizeDropsThatCamera) {
  const fs::path& take = studioTake();
  carving::TakeSource src;
  src.take_dir = take;
  src.rig_path = take / "truth" / "rig.json";
  src.main_poses = take / "truth" / "main_poses.jsonl";
  const carving::Take t(src);
  live::FrameLoopOptions o;
  o.witness_bin = 2;
  live::FrameLoop loop(t.rig(), readCgCamera(take / "cg" / "camera.json"), o);
  const live::TakeReader reader(t, loop, live::TakeInputOptions{});
  live::FrameState s;
  reader.read(1, s);
  ASSERT_GE(s.witness_plates.size(), 2u);
  const cv::Size full = s.witness_plates[0].size();
  cv::resize(s.witness_plates[0], s.witness_plates[0], cv::Size(full.width / 2, full.height / 2), 0, 0, cv::INTER_AREA);
  loop.run(s);
  EXPECT_NE(s.dropped[0].find("plate is " + std::to_string(full.width / 2) + "x" + std::to_string(full.height / 2) +
                              " but the camera is " + std::to_string(full.width) + "x" + std::to_string(full.height)),
            std::string::npos)
      << s.dropped[0];
  for (size_t i = 1; i < s.dropped.size(); ++i) EXPECT_EQ(s.dropped[i], "") << loop.carveCameras()[i];
  EXPECT_FALSE(s.composite.bgr.empty());
  o.witness_bin = 9;
  EXPECT_THROW(live::FrameLoop(t.rig(), readCgCamera(take / "cg" / "camera.json"), o), Error);
}

// The plug-in point of later stages (prop tracking goes after "depth"): an inserted stage runs
// in its place, sees the stages before it done and the ones after it not yet, and is timed.
TEST(FrameLoop, InsertedStageRunsInItsPlaceAndIsTimed) {
  const fs::path& take = studioTake();
  carving::TakeSource src;
  src.take_dir = take;
  src.rig_path = take / "truth" / "rig.json";
  src.main_poses = take / "truth" / "main_poses.jsonl";
  const carving::Take t(src);
  live::FrameLoop loop(t.rig(), readCgCamera(take / "cg" / "camera.json"), live::FrameLoopOptions{});
  bool saw_depth = false, saw_composite = true;
  loop.insertStage("depth", "probe", [&](live::FrameState& s) {
    saw_depth = !s.main_depth.empty();
    saw_composite = !s.composite.bgr.empty();
  });
  EXPECT_EQ(loop.stages(), (std::vector<std::string>{"key", "carve", "depth", "probe", "composite"}));
  EXPECT_THROW(loop.insertStage("nosuch", "x", [](live::FrameState&) {}), Error);
  // Work of the probe stage pooled with the keys: the items planned (pixels > 0) run once each,
  // before the stages after "key", and their share of the pool's time is the probe's.
  std::vector<int> runs(3, 0);
  cv::Mat work(1000, 1000, CV_32F, cv::Scalar(1)), blurred;
  loop.poolWithKey({"probe", [](live::FrameState&) { return std::vector<long long>{100, 0, 100}; },
                    [&](int i) {
                      ++runs[static_cast<size_t>(i)];
                      cv::Mat b;
                      cv::GaussianBlur(work, b, cv::Size(31, 31), 0);
                    }});
  EXPECT_THROW(loop.poolWithKey({"nosuch", {}, {}}), Error);
  EXPECT_THROW(loop.poolWithKey({"key", {}, {}}), Error);
  bool items_done_before_carve = false;
  loop.insertStage("key", "check", [&](live::FrameState&) { items_done_before_carve = runs == std::vector<int>{1, 0, 1}; });
  const live::TakeReader reader(t, loop, live::TakeInputOptions{});
  live::FrameState s;
  reader.read(1, s);
  const std::vector<live::StageTime> times = loop.run(s);
  ASSERT_EQ(times.size(), 6u);
  EXPECT_EQ(times[0].stage, "key");
  EXPECT_EQ(times[4].stage, "probe");
  EXPECT_TRUE(items_done_before_carve);
  EXPECT_EQ(runs, (std::vector<int>{1, 0, 1}));
  EXPECT_GT(times[0].ms, 0);
  EXPECT_GT(times[4].ms, 0);
  EXPECT_GT(times[4].cpu_ms, 0);
  EXPECT_TRUE(saw_depth);
  EXPECT_FALSE(saw_composite);
  EXPECT_FALSE(s.composite.bgr.empty());
}

// `previz run --live`: every camera of the take as a video file written by cv::VideoWriter
// (MJPG), read back through VideoCapture in lock step. Unpaced, every frame is processed and the
// composite matches the truth as from the PNG plates; paced at a camera rate far above what the
// loop sustains, late frames are dropped and counted, never queued.
TEST(RunLive, ReadsVideoFilesInLockStepAndDropsLateFrames) {
  const fs::path& take = studioTake();
  const fs::path dir = previz::test::scratchDir("composite", "live");
  carving::TakeSource src;
  src.take_dir = take;
  src.rig_path = take / "truth" / "rig.json";
  src.main_poses = take / "truth" / "main_poses.jsonl";
  const carving::Take t(src);
  const Camera cg = readCgCamera(take / "cg" / "camera.json");
  live::FrameLoop loop(t.rig(), cg, live::FrameLoopOptions{});
  const live::TakeReader reader(t, loop, live::TakeInputOptions{});
  live::LiveOptions live;
  std::vector<std::string> names = loop.carveCameras();
  names.push_back(loop.mainCamera());
  for (const std::string& name : names) {
    const fs::path video = dir / (name + ".avi");
    cv::VideoWriter w(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 24.0,
                      cv::Size(t.rig().at(name).camera.width, t.rig().at(name).camera.height));
    ASSERT_TRUE(w.isOpened()) << video;
    for (int f : t.frames()) w.write(readImage(take / "cams" / name / (stem(f) + ".png"), cv::IMREAD_COLOR));
    w.release();
    live.sources[name] = video.string();
  }

  live.pace = false;
  {
    live::LiveReader in(loop, reader, live);
    int frames = 0;
    double min_psnr = 99;
    for (live::FrameState s; in.next(s); ++frames) {
      EXPECT_EQ(s.frame, frames);
      loop.run(s);
      const cv::Mat truth = readImage(take / "truth" / "composite" / (stem(s.frame) + ".png"), cv::IMREAD_COLOR);
      const cv::Mat mask = readImage(take / "truth" / "masks" / "main" / (stem(s.frame) + ".png"), cv::IMREAD_GRAYSCALE);
      const cv::Rect box = cv::boundingRect(mask);
      min_psnr = std::min(min_psnr, psnr(s.composite.bgr(box), truth(box)));
    }
    std::printf("  live, unpaced: %d frames, %d dropped, min PSNR over the actor bbox %.2f dB (MJPG plates)\n", frames,
                in.dropped(), min_psnr);
    EXPECT_EQ(frames, static_cast<int>(t.frames().size()));
    EXPECT_EQ(in.dropped(), 0);
    // MJPG (OpenCV's default quality 95) costs the plates about 2 dB against the PNG run
    // (32.6 dB min over the same frames): a bar 2 dB under item 1's still fails on a broken key,
    // depth or frame order (frames out of step give < 20 dB).
    EXPECT_GE(min_psnr, 28.0);
  }
  // The same videos named by the take itself (take.json "sources": "live:..."; the CG and the
  // main camera's poses from the studio take): no --live needed.
  {
    const fs::path live_take = dir / "live_take";
    writeJsonAtomic(live_take / "take.json", {{"sources", {{"*", "live:" + (dir / "{camera}.avi").string()}}}});
    carving::TakeSource lsrc = src;
    lsrc.take_dir = live_take;
    const carving::Take lt(lsrc);
    EXPECT_EQ(lt.streams().stream("main").kind, take::SourceKind::kLive);
    live::TakeInputOptions lio;
    lio.cg_dir = take / "cg";
    const live::TakeReader lreader(lt, loop, lio);
    live::LiveOptions from_take;
    from_take.pace = false;
    live::LiveReader in(loop, lreader, from_take);
    int frames = 0;
    for (live::FrameState s; in.next(s); ++frames) EXPECT_EQ(s.frame, frames);
    EXPECT_EQ(frames, static_cast<int>(t.frames().size()));
  }
  live.pace = true;
  live.fps = 1000;  // cameras far faster than the loop
  {
    live::LiveReader in(loop, reader, live);
    std::vector<int> seen;
    for (live::FrameState s; in.next(s);) {
      seen.push_back(s.frame);
      loop.run(s);
    }
    std::printf("  live, paced at 1000 fps: processed frames");
    for (int f : seen) std::printf(" %d", f);
    std::printf(", %d dropped\n", in.dropped());
    ASSERT_FALSE(seen.empty());
    EXPECT_EQ(seen.front(), 0);
    EXPECT_GT(in.dropped(), 0);
    EXPECT_EQ(in.delivered(), static_cast<int>(seen.size()));
    EXPECT_LE(in.delivered() + in.dropped(), static_cast<int>(t.frames().size()));
    EXPECT_GE(in.delivered() + in.dropped(), static_cast<int>(t.frames().size()) - 1);
  }
  live.sources[loop.mainCamera()] = (dir / "nosuch.avi").string();
  try {
    live::LiveReader in(loop, reader, live);
    FAIL() << "opened a missing file";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, loop.mainCamera());
  }
}

// Issue 7 item 1 with the cameras previz calibrated itself: the multicam.capture fixture's rig
// capture (the studio rig at its design sizes, AprilGrid board rendered and detected, noise
// sigma 2, floor frames) solved by calibrateRig with every camera's intrinsics free, started
// from intrinsics 3 % off in focal length, 6-8 px off in principal point and no distortion.
// The calibrated rig (scaled to the take's sizes) carves and composites; the main camera's
// dolly motion comes as a camera tracker would give it, T_main0_main(f) relative to where main
// stood when the rig was calibrated (here derived from truth/main_poses.jsonl).
TEST(RunCalibratedRig, CompositeMatchesTruthWithTheRigPrevizCalibrated) {
  const fs::path capture(PREVIZ_MULTICAM_CAPTURE);
  ASSERT_TRUE(fs::exists(capture / "main.json")) << "run the multicam.capture CTest fixture first";
  const Rig capture_truth = readRig(capture / "truth_rig.json");
  const fs::path& take = studioTake();
  const Rig take_truth = readRig(take / "truth" / "rig.json");
  // The fixture's rig must be the studio preset's: same cameras, same witness poses.
  ASSERT_EQ(capture_truth.cameras.size(), take_truth.cameras.size());
  for (const RigCamera& rc : take_truth.cameras) {
    const RigCamera& c = capture_truth.at(rc.camera.name);
    if (rc.role == "witness") {
      ASSERT_LT(translationDistance(c.T_world_cam, rc.T_world_cam), 1e-9) << rc.camera.name;
      ASSERT_NEAR(c.camera.fx * rc.camera.width / c.camera.width, rc.camera.fx, 1e-6) << rc.camera.name;
    }
  }

  Rig initial = capture_truth;
  for (RigCamera& rc : initial.cameras) {
    rc.T_world_cam = Pose::Identity();
    rc.camera.fx *= 1.03;
    rc.camera.fy *= 1.03;
    rc.camera.cx += 8;
    rc.camera.cy -= 6;
    rc.camera.dist = Distortion{};
  }
  multicam::RigCalibOptions options;
  options.estimate_intrinsics = {"*"};
  const multicam::RigCalibResult calib =
      multicam::calibrateRig(multicam::readObservations(capture / "main.json"), initial, options);
  std::printf("  rig calibrated: RMS %.3f px, world from floor %d, %.1f s\n", calib.rms_px, calib.world_from_floor,
              calib.solve_ms / 1000);
  Rig calibrated = calib.rig;
  for (RigCamera& rc : calibrated.cameras) {
    const RigCamera& t = capture_truth.at(rc.camera.name);
    const double s = double(take_truth.at(rc.camera.name).camera.width) / rc.camera.width;
    std::printf("    %-10s fx %+.3f %%, cx %+.2f px, k1 %+.4f, position %.1f mm, rotation %.3f deg\n",
                rc.camera.name.c_str(), 100 * (rc.camera.fx / t.camera.fx - 1), rc.camera.cx - t.camera.cx,
                rc.camera.dist.k1 - t.camera.dist.k1, 1e3 * translationDistance(rc.T_world_cam, t.T_world_cam),
                rotationDistance(rc.T_world_cam, t.T_world_cam) * 180 / M_PI);
    rc.camera = rc.camera.scaled(s, s);
    rc.camera.width = take_truth.at(rc.camera.name).camera.width;
    rc.camera.height = take_truth.at(rc.camera.name).camera.height;
  }
  const fs::path dir = previz::test::scratchDir("composite", "calibrated");
  writeRig(calibrated, dir / "rig.json");

  // The tracker's poses: motion of main from where it stood during the rig capture.
  const Pose T_world_main0 = capture_truth.at("main").T_world_cam;
  std::string lines;
  for (const std::string& line : [&] {
         std::vector<std::string> v;
         std::istringstream in(readTextFile(take / "truth" / "main_poses.jsonl"));
         for (std::string l; std::getline(in, l);)
           if (!l.empty()) v.push_back(l);
         return v;
       }()) {
    const nlohmann::json j = nlohmann::json::parse(line);
    const Pose T_main0_main = T_world_main0.inverse() * poseFromJson(j.at("T_world_cam"));
    lines += nlohmann::json{{"frame", j.at("frame")}, {"T_main0_main", poseToJson(T_main0_main)}}.dump() + "\n";
  }
  writeFileAtomic(dir / "tracked_main.jsonl", lines);

  const TakeMeasure m = measureTake(take, dir / "rig.json", dir / "tracked_main.jsonl", "calibrated rig, tracked main");
  ASSERT_EQ(m.frames.size(), 5u);
  EXPECT_GE(m.min_psnr_db, 30.0);
  EXPECT_LE(m.wrongFraction(), 0.005);
}

}  // namespace
}  // namespace previz::composite::test
