// PropTracker over rendered studio frames. Issue 6 item 3: ROI tracking finds the same tags as a
// full-frame search of the same images (the test asserts the tags; the speed is the benchmark's,
// bench/tracking_bench.cpp). A prop that disappears is reported lost, with no pose, until it is
// seen again; one that is not where it was predicted is found again in the same frame.
#include <gtest/gtest.h>

#include <cstdio>
#include <set>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "studio_fixture.h"
#include "tracking/tracker.h"

namespace previz::tracking {
namespace {

constexpr double kFps = 24.0;

std::set<int> ids(const std::vector<TagDetection>& d) {
  std::set<int> s;
  for (const auto& x : d) s.insert(x.id);
  return s;
}

TEST(PropTracker, RoiSearchFindsTheSameTagsAsFullFrames) {
  test::StudioFixture fx(std::filesystem::path(PREVIZ_TEST_TMP) / "tracking_stage_cache");
  TrackerOptions o;
  o.full_frame_every = 0;  // ROI on every frame after the first: the case to check
  o.threads = 2;
  PropTracker tracker(fx.rig.cameras, test::studioProps(fx.studio), o);
  std::vector<TagDetector> full;
  for (int c = 0; c < fx.cameras(); ++c) full.emplace_back(DetectorOptions{});
  int frames = 0, same = 0, roi_frames = 0, tags = 0;
  long long roi_pixels = 0, full_pixels = 0;
  // 16 frames, every other frame of the take (the crate moves twice as far between frames as
  // at 24 fps) over 1.3 s where it moves fastest along its path.
  for (int f = 0; f < 16; ++f) {
    const double t = 2.0 + 2 * f / kFps;
    const std::vector<cv::Mat> images = fx.renderTake(t, f, 24);
    const TrackFrame r = tracker.track(f, t, images);
    ASSERT_TRUE(r.props[0].tracked) << "frame " << f;
    bool match = true;
    for (int c = 0; c < fx.cameras(); ++c) {
      const std::set<int> whole = ids(full[static_cast<size_t>(c)].detect(images[static_cast<size_t>(c)]));
      // The tracker's detections of this camera: the tags its corners came from are not exposed
      // per camera, so search the tracker's own regions again with the same settings.
      TagDetector again{DetectorOptions{}};
      const std::set<int> roi = ids(again.detect(images[static_cast<size_t>(c)], r.search[static_cast<size_t>(c)].rois));
      EXPECT_EQ(static_cast<int>(roi.size()), r.search[static_cast<size_t>(c)].detections);
      match = match && roi == whole;
      tags += static_cast<int>(whole.size());
      roi_pixels += r.search[static_cast<size_t>(c)].pixels;
      full_pixels += static_cast<long long>(images[static_cast<size_t>(c)].total());
    }
    ++frames;
    same += match ? 1 : 0;
    roi_frames += r.full_frame ? 0 : 1;
  }
  std::printf("roi: %d/%d frames with the same tags as full frames (%d ROI frames, %.1f tags/frame, ROI searched "
              "%.2f %% of the pixels)\n",
              same, frames, roi_frames, double(tags) / frames, 100.0 * roi_pixels / full_pixels);
  EXPECT_EQ(roi_frames, frames - 1);
  EXPECT_GE(same, static_cast<int>(std::ceil(0.99 * frames)));
}

// track() in steps (begin, each camera's search in any order, finish), as the live loop runs
// them among its keys: the same frames as track(), each camera planned with the pixels it then
// searches; a step out of order is an error, and a begin() whose frame was never finished (the
// caller's frame failed) is forgotten by the next one.
TEST(PropTracker, StepsGiveTheSameFramesAsTrack) {
  test::StudioFixture fx(std::filesystem::path(PREVIZ_TEST_TMP) / "tracking_stage_cache");
  TrackerOptions o;
  o.threads = 2;
  o.full_frame_every = 3;  // whole-frame and region searches both
  PropTracker whole(fx.rig.cameras, test::studioProps(fx.studio), o);
  PropTracker steps(fx.rig.cameras, test::studioProps(fx.studio), o);
  EXPECT_THROW(steps.finish(), Error);
  EXPECT_THROW(steps.search(0), Error);
  const int n = fx.cameras();
  for (int f = 0; f < 6; ++f) {
    const double t = 2.0 + f / kFps;
    const std::vector<cv::Mat> images = fx.renderTake(t, f, 24);
    const TrackFrame a = whole.track(f, t, images);
    if (f == 2) steps.begin(f, t, images);  // abandoned: the next begin() starts over
    const std::vector<long long> px = steps.begin(f, t, images);
    ASSERT_EQ(static_cast<int>(px.size()), n);
    EXPECT_THROW(steps.search(n), Error);
    for (int c = n - 1; c >= 0; --c) steps.search(c);  // any order
    const TrackFrame b = steps.finish();
    EXPECT_THROW(steps.finish(), Error);  // once a frame
    nlohmann::json ja = trackFrameToJson(a), jb = trackFrameToJson(b);
    ja.erase("ms");
    jb.erase("ms");
    EXPECT_EQ(ja, jb) << "frame " << f;
    ASSERT_TRUE(b.props[0].tracked) << "frame " << f;
    for (int c = 0; c < n; ++c) EXPECT_EQ(px[static_cast<size_t>(c)], b.search[static_cast<size_t>(c)].pixels);
    EXPECT_GT(b.detect_ms, 0);
    EXPECT_DOUBLE_EQ(b.total_ms, b.detect_ms + b.solve_ms);
  }
}

// The periodic whole-frame search is staggered over the cameras: each camera searches its whole
// frame every full_frame_every frames, never all of them on the same frame (which cost a 66 ms
// frame every 30 in the live loop: 8 whole 1280x720 frames at once).
TEST(PropTracker, StaggersThePeriodicWholeFrameSearchOverCameras) {
  test::StudioFixture fx(std::filesystem::path(PREVIZ_TEST_TMP) / "tracking_stage_cache");
  const double t = 3.0;
  const Pose T = fx.studio.T_world_prop(t);
  const std::vector<cv::Mat> images = fx.renderTake(t, 0);  // the same frame every time
  TrackerOptions o;
  o.threads = 2;
  o.full_frame_every = 3;  // fewer than the cameras: some frames hold two whole-frame searches
  const int n = fx.cameras(), every = o.full_frame_every;
  ASSERT_GT(n, every);
  PropTracker tracker(fx.rig.cameras, test::studioProps(fx.studio), o);
  std::vector<std::vector<int>> whole_at(static_cast<size_t>(n));  // frames each camera searched whole
  constexpr int kFrames = 13;
  for (int f = 0; f < kFrames; ++f) {
    const TrackFrame r = tracker.track(f, f / kFps, images);
    ASSERT_TRUE(r.props[0].tracked) << "frame " << f;
    EXPECT_LT(translationDistance(r.props[0].T_world_prop, T), 0.002) << "frame " << f;
    int whole = 0;
    for (int c = 0; c < n; ++c) {
      const CameraSearch& s = r.search[static_cast<size_t>(c)];
      if (!s.full_frame) continue;
      ++whole;
      ASSERT_EQ(s.rois.size(), 1u);
      EXPECT_EQ(s.pixels, static_cast<long long>(images[static_cast<size_t>(c)].total()));
      whole_at[static_cast<size_t>(c)].push_back(f);
    }
    EXPECT_EQ(trackFrameToJson(r)["whole_frame_cameras"], whole);
    if (f == 0) {
      EXPECT_TRUE(r.full_frame);  // first frame: every camera
      EXPECT_EQ(whole, n);
    } else {
      EXPECT_FALSE(r.full_frame) << "frame " << f;
      EXPECT_LE(whole, (n + every - 1) / every) << "frame " << f;
    }
  }
  for (int c = 0; c < n; ++c) {
    const std::vector<int>& at = whole_at[static_cast<size_t>(c)];
    ASSERT_GE(at.size(), 4u) << "camera " << c;  // frame 0, then every 3 frames of 12
    EXPECT_EQ(at[0], 0);
    EXPECT_LE(at[1], every) << "camera " << c;
    for (size_t i = 2; i < at.size(); ++i) EXPECT_EQ(at[i] - at[i - 1], every) << "camera " << c;
  }
}

TEST(PropTracker, DisappearingPropIsLostWithoutAPoseThenReacquired) {
  test::StudioFixture fx(std::filesystem::path(PREVIZ_TEST_TMP) / "tracking_stage_cache");
  const double t = 3.0;
  const Pose T = fx.studio.T_world_prop(t);
  const synth::Scene with = fx.studio.sceneAt(t, synth::kLayersPlate);
  std::vector<cv::Mat> seen(static_cast<size_t>(fx.cameras())), empty(seen.size());
  test::parallelFor(fx.cameras(), [&](int c) {
    seen[static_cast<size_t>(c)] = fx.renderWith(c, with, T, 0);
    fx.renderStage();
    empty[static_cast<size_t>(c)] = fx.stage[static_cast<size_t>(c)].clone();
  });
  TrackerOptions o;
  o.threads = 2;
  PropTracker tracker(fx.rig.cameras, test::studioProps(fx.studio), o);
  const TrackFrame a = tracker.track(0, 0.0, seen);
  ASSERT_TRUE(a.props[0].tracked);
  EXPECT_TRUE(a.props[0].reacquired);
  const TrackFrame b = tracker.track(1, 1 / kFps, seen);
  ASSERT_TRUE(b.props[0].tracked);
  EXPECT_FALSE(b.props[0].reacquired);
  EXPECT_FALSE(b.full_frame);
  const TrackFrame c = tracker.track(2, 2 / kFps, empty);
  EXPECT_FALSE(c.props[0].tracked);
  const nlohmann::json j = trackFrameToJson(c);
  EXPECT_EQ(j["props"][0]["state"], "lost");
  EXPECT_FALSE(j["props"][0].contains("T_world_prop"));  // never a stale pose
  EXPECT_EQ(j["props"][0]["reason"], "no tag of this prop seen");
  // Missing cameras are reported, the others still track.
  std::vector<cv::Mat> partial = seen;
  partial[0] = cv::Mat();
  const TrackFrame d = tracker.track(3, 3 / kFps, partial);
  EXPECT_TRUE(d.full_frame);  // after a loss
  ASSERT_TRUE(d.props[0].tracked);
  EXPECT_TRUE(d.props[0].reacquired);
  EXPECT_EQ(d.search[0].failure, "no image");
  EXPECT_LT(translationDistance(d.props[0].T_world_prop, T), 0.002);
  const nlohmann::json jd = trackFrameToJson(d);
  EXPECT_EQ(jd["camera_failures"][0]["camera"], fx.rig.cameras[0].camera.name);
  // Wrong image count is an error naming the frame.
  try {
    tracker.track(4, 4 / kFps, {seen[0]});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("frame 4"), std::string::npos) << e.what();
  }
}

// A prop that is not where the filter predicts it (here it jumps: the take's frames at t = 3 s,
// then the frame at t = 7.5 s handed over as the next frame at 24 fps, 1.6 m away) is not lost:
// its predicted regions hold none of its tags, so the cameras search their whole frames again in
// the same frame, and the pose is solved afresh, the filter restarted (reacquired). (After a
// shorter jump, 0.5 to 1.4 m, one or two cameras' regions still catch a tag, and that solve
// tracks it.)
TEST(PropTracker, PropOutsideItsPredictedRegionsIsFoundInTheSameFrame) {
  test::StudioFixture fx(std::filesystem::path(PREVIZ_TEST_TMP) / "tracking_stage_cache");
  const double t0 = 3.0, t1 = 7.5;
  const Pose T0 = fx.studio.T_world_prop(t0), T1 = fx.studio.T_world_prop(t1);
  ASSERT_GT(translationDistance(T0, T1), 1.5);  // far beyond the regions' margins
  const std::vector<cv::Mat> before = fx.renderTake(t0, 0), after = fx.renderTake(t1, 2);
  TrackerOptions o;
  o.threads = 2;
  o.full_frame_every = 0;  // no periodic whole-frame search that could find it by chance
  PropTracker tracker(fx.rig.cameras, test::studioProps(fx.studio), o);
  ASSERT_TRUE(tracker.track(0, 0.0, before).props[0].tracked);
  const TrackFrame steady = tracker.track(1, 1 / kFps, before);
  ASSERT_TRUE(steady.props[0].tracked);
  EXPECT_FALSE(steady.full_frame);
  EXPECT_EQ(steady.rescanned_cameras, 0);

  const TrackFrame jump = tracker.track(2, 2 / kFps, after);
  ASSERT_TRUE(jump.props[0].tracked) << jump.props[0].measured.failure;
  EXPECT_TRUE(jump.props[0].reacquired);
  EXPECT_EQ(jump.rescanned_cameras, fx.cameras());  // every camera had searched regions only
  EXPECT_TRUE(jump.full_frame);
  for (const CameraSearch& s : jump.search) EXPECT_TRUE(s.full_frame) << s.camera;
  // The new place, not a blend with the old one (the filter restarted).
  EXPECT_LT(translationDistance(jump.props[0].T_world_prop, T1), 0.002);
  EXPECT_EQ(trackFrameToJson(jump)["rescanned_cameras"], fx.cameras());

  // And it is tracked on from there in its new regions.
  const TrackFrame next = tracker.track(3, 3 / kFps, after);
  ASSERT_TRUE(next.props[0].tracked);
  EXPECT_FALSE(next.props[0].reacquired);
  EXPECT_FALSE(next.full_frame);
  EXPECT_EQ(next.rescanned_cameras, 0);
  EXPECT_LT(translationDistance(next.props[0].T_world_prop, T1), 0.002);
}

TEST(PropTracker, TagsOfNoPropAreCountedAndIgnored) {
  test::StudioFixture fx(std::filesystem::path(PREVIZ_TEST_TMP) / "tracking_stage_cache");
  const double t = 3.0;
  const synth::Scene with = fx.studio.sceneAt(t, synth::kLayersPlate);
  const Pose T = fx.studio.T_world_prop(t);
  std::vector<cv::Mat> images(static_cast<size_t>(fx.cameras()));
  test::parallelFor(fx.cameras(), [&](int c) { images[static_cast<size_t>(c)] = fx.renderWith(c, with, T, 0); });
  // A props file that knows only tags 0 and 1 of the crate.
  PropSet props = test::studioProps(fx.studio);
  props.props[0].tags.resize(2);
  PropTracker tracker(fx.rig.cameras, props, TrackerOptions{});
  const TrackFrame r = tracker.track(0, t, images);
  int total = 0;
  for (const auto& s : r.search) total += s.detections;
  std::printf("unknown: %d of %d decoded tags belong to no prop\n", r.unknown_tags, total);
  EXPECT_GT(r.unknown_tags, 0);
  EXPECT_LT(r.unknown_tags, total);
}

TEST(PropTracker, BadOptionsNameTheField) {
  TrackerOptions o;
  o.detector.decimate = 0.5f;
  try {
    o.validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("decimate"), std::string::npos);
  }
  o = {};
  o.per_camera["witness02"].sigma = -1;
  try {
    o.validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("witness02"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace previz::tracking
