// RigCapture: the board region traced over the cached stage equals a full render, the noise is
// what it says, delays and bumps reach both the images and the truth, and the truth is where a
// detector finds the board.
#include "datasets/rig_capture.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "calib/detect.h"
#include "core/error.h"
#include "datasets/detail/board_view.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace previz::synth {
namespace {

// Three witnesses at 480x270 (no main camera): cheap backgrounds, the real layout.
RigCaptureOptions smallOptions() {
  RigCaptureOptions o;
  o.rig.witness_cameras = 3;
  o.rig.witness_width = 480;
  o.rig.witness_height = 270;
  o.rig.with_main = false;
  o.rig.seed = 3;
  o.board_seed = 4;
  o.frames = 30;
  o.noise_sigma = 0.0;
  return o;
}

Scene emptyStage(std::uint64_t seed) {
  StudioConfig config;
  config.seed = seed;
  config.with_actor = false;
  config.with_prop = false;
  return Studio(config).sceneAt(0.0, kLayerStage);
}

// The scene a camera-frame shows, built independently of RigCapture: stage + board.
Scene sceneOf(const RigCapture& capture, const RigCaptureOptions& o, int camera, int frame) {
  Scene scene = emptyStage(o.rig.seed);
  const auto board = makeBoard(capture.board(), capture.T_world_board(camera, frame));
  scene.add(capture.showsFloorBoard(camera, frame) ? onTopOf(board) : board);
  return scene;
}

struct Diff {
  int max = 0;
  long long count = 0;  // channels that differ
};
Diff compare(const cv::Mat& a, const cv::Mat& b) {
  Diff d;
  EXPECT_EQ(a.size(), b.size());
  EXPECT_EQ(a.type(), b.type());
  if (a.size() != b.size() || a.type() != b.type()) return {255, -1};
  for (size_t i = 0; i < a.total() * a.channels(); ++i) {
    const int e = std::abs(int(a.data[i]) - int(b.data[i]));
    d.max = std::max(d.max, e);
    d.count += e > 0;
  }
  return d;
}

// Cosine of the angle between the camera's line of sight to the board centre and the board's
// normal (1: seen face on).
double facing(const RigCapture& capture, int camera, int frame) {
  const Pose T = capture.T_world_board(camera, frame);
  const Eigen::Vector2d size = capture.board().size_m();
  const Eigen::Vector3d centre = T * Eigen::Vector3d(0.5 * size.x(), 0.5 * size.y(), 0.0);
  const Eigen::Vector3d eye = capture.rig().cameras[camera].T_world_cam.translation();
  return (centre - eye).normalized().dot(T.linear().col(2));  // board z points away from its reader
}

// A waving frame from 'start' on in which the camera sees at least 'min_points' board points,
// facing it within acos(min_facing).
int visibleFrame(const RigCapture& capture, int camera, size_t min_points, int start = 0,
                 double min_facing = -1.0) {
  for (int f = start; f < capture.frames(); ++f) {
    if (capture.isFloorFrame(f) || facing(capture, camera, f) < min_facing) continue;
    if (capture.truth(camera, f).size() >= min_points) return f;
  }
  return -1;
}

// renderView of the same camera-frame vs the capture. The traced pixels see the same rays (the
// crop's principal point moves by whole pixels), so they agree to the bit but for the last bits
// of the warm-started lens inversion; the rest is the cached stage, itself a full render.
void expectRegionEqualsFull(const RigCaptureOptions& o, const std::vector<int>& cameras) {
  const RigCapture capture(o);
  const size_t n_points = boardPoints(capture.board()).size();
  for (int camera : cameras) {
    const int waving = visibleFrame(capture, camera, n_points / 2);
    ASSERT_GE(waving, 0) << "camera " << camera << " never sees half the board";
    for (int frame : {waving, o.frames - 1}) {
      const RigCamera& rc = capture.rig().cameras[camera];
      // The board is in the picture: the comparison covers traced pixels.
      const size_t seen = capture.truth(camera, frame).size();
      ASSERT_GE(seen, n_points / 2) << rc.camera.name << " frame " << frame;
      RenderOptions ro;
      ro.samples_per_pixel = o.samples_per_pixel;
      ro.blur_sigma_px = o.blur_sigma_px;
      if (auto g = o.gain.find(rc.camera.name); g != o.gain.end()) ro.gain = g->second;
      ro.truth = false;
      const cv::Mat full = renderView(rc.camera, rc.T_world_cam, sceneOf(capture, o, camera, frame), ro).bgr;
      const Diff d = compare(full, capture.render(camera, frame));
      std::printf("%s frame %d%s (%zu board points seen), blur %.1f gain %.2f: max |region - full| "
                  "= %d grey levels, %lld of %zu channels differ\n",
                  rc.camera.name.c_str(), frame, capture.isFloorFrame(frame) ? " (floor)" : "",
                  seen, ro.blur_sigma_px, ro.gain, d.max, d.count, full.total() * 3);
      EXPECT_LE(d.max, 1);
      EXPECT_LE(d.count, static_cast<long long>(1e-4 * full.total() * 3));
    }
  }
}

TEST(RigCapture, RegionRenderEqualsFullRenderWithoutNoise) {
  expectRegionEqualsFull(smallOptions(), {0, 2});
}

// Defocus runs over a window around the board on the cached linear stage; gain scales linear
// light before it (as renderView applies both).
TEST(RigCapture, RegionRenderEqualsFullRenderWithBlurAndGain) {
  RigCaptureOptions o = smallOptions();
  o.blur_sigma_px = 1.5;
  o.gain["witness02"] = 1.3;
  expectRegionEqualsFull(o, {1});
}

// A board the camera cannot see leaves the cached stage untouched, and nothing is traced.
TEST(RigCapture, BoardOutOfViewLeavesTheStage) {
  const RigCaptureOptions o = smallOptions();
  const RigCamera rc = studioRig(o.rig, StudioConfig{}.take_duration_s, false).cameras[0];
  detail::BoardViewOptions vo;
  const detail::BoardView view(rc.camera, rc.T_world_cam, emptyStage(o.rig.seed), vo);
  const BoardSpec spec = rigBoard(BoardType::kAprilGrid);
  // Behind the camera, then beside it (in front of the camera plane, outside the view).
  const Pose behind = rc.T_world_cam * Pose(Eigen::Translation3d(0, 0, -2.0));
  const Pose beside = rc.T_world_cam * Pose(Eigen::Translation3d(-8.0, 0, 1.0));
  for (const Pose& T_world_board : {behind, beside}) {
    detail::BoardViewStats stats;
    const cv::Mat image = view.render(spec, T_world_board, false, 1, 0, 0, &stats);
    EXPECT_FALSE(stats.board_in_view);
    EXPECT_EQ(stats.traced_pixels, 0);
    EXPECT_EQ(compare(image, view.background()).max, 0);
  }
}

// Noise: Gaussian of the requested sigma, zero mean, a pure function of (seed, camera, frame),
// and the same whether frames are rendered serially or from an OpenMP loop.
TEST(RigCapture, NoiseIsGaussianDeterministicAndThreadSafe) {
  RigCaptureOptions o = smallOptions();
  const RigCapture clean(o);
  o.noise_sigma = 2.0;
  const RigCapture noisy(o);
  const int frame = visibleFrame(clean, 0, 1);
  ASSERT_GE(frame, 0);
  const cv::Mat a = clean.render(0, frame), b = noisy.render(0, frame);
  double sum = 0, sum2 = 0, sum4 = 0;
  long long n = 0;
  for (size_t i = 0; i < a.total() * 3; ++i) {
    if (a.data[i] < 25 || a.data[i] > 230) continue;  // away from clipping
    const double e = double(b.data[i]) - a.data[i];
    sum += e, sum2 += e * e, sum4 += e * e * e * e;
    ++n;
  }
  const double mean = sum / n, var = sum2 / n - mean * mean;
  // Rounding twice (clean, noisy) adds ~1/12 to the variance of the difference; the excess
  // kurtosis of a Gaussian is 0 (a uniform's would be -1.2).
  const double sd = std::sqrt(var - 1.0 / 12.0);
  const double kurtosis = (sum4 / n) / (var * var) - 3.0;
  std::printf("noise sigma 2: measured %.3f (mean %.3f, excess kurtosis %.3f) over %lld channels\n",
              sd, mean, kurtosis, n);
  ASSERT_GT(n, 100000);
  EXPECT_NEAR(sd, 2.0, 0.05);
  EXPECT_LT(std::abs(mean), 0.05);
  EXPECT_NEAR(kurtosis, 0.0, 0.15);
  // Deterministic, and another frame draws other noise.
  EXPECT_EQ(compare(b, noisy.render(0, frame)).max, 0);
  const int other = frame + 1 < o.frames ? frame + 1 : frame - 1;
  const cv::Mat other_clean = clean.render(0, other), other_noisy = noisy.render(0, other);
  long long same = 0;
  for (size_t i = 0; i < b.total() * 3; ++i) {
    same += (int(b.data[i]) - a.data[i]) == (int(other_noisy.data[i]) - other_clean.data[i]);
  }
  EXPECT_LT(same, static_cast<long long>(0.3 * b.total() * 3));  // ~0.2 for independent draws

  // Parallel renders (several threads on one camera's first render too) equal serial ones.
  const RigCapture fresh(o);
  const int cameras = 3, frames = 6;
  std::vector<cv::Mat> parallel(cameras * frames);
#pragma omp parallel for schedule(dynamic, 1) num_threads(4)
  for (int k = 0; k < cameras * frames; ++k) parallel[k] = fresh.render(k % cameras, k / cameras);
  for (int k = 0; k < cameras * frames; ++k) {
    EXPECT_EQ(compare(parallel[k], noisy.render(k % cameras, k / cameras)).max, 0) << "item " << k;
  }
}

// A late camera shows an earlier board: pose, truth and image of frame f are those of frame
// f - delay of a capture without the delay; other cameras are untouched.
TEST(RigCapture, DelayShowsTheBoardOfAnEarlierFrame) {
  RigCaptureOptions o = smallOptions();
  const RigCapture plain(o);
  constexpr int kDelay = 3;
  o.delay_frames["witness02"] = kDelay;
  const RigCapture late(o);
  const int camera = 1;
  EXPECT_EQ(late.rig().cameras[camera].camera.name, "witness02");
  int image_checks = 0;
  for (int f : {0, 2, 3, 10, 17, o.frames - 1}) {
    const int shown = std::max(0, f - kDelay);
    EXPECT_TRUE(late.T_world_board(camera, f).isApprox(plain.T_world_board(camera, shown), 0))
        << "frame " << f;
    EXPECT_EQ(late.showsFloorBoard(camera, f), plain.isFloorFrame(shown)) << "frame " << f;
    const auto truth = late.truth(camera, f), expected = plain.truth(camera, shown);
    ASSERT_EQ(truth.size(), expected.size()) << "frame " << f;
    for (size_t i = 0; i < truth.size(); ++i) {
      EXPECT_EQ(truth[i].id, expected[i].id);
      EXPECT_EQ(truth[i].px, expected[i].px);
    }
    // Other cameras keep their frame.
    EXPECT_TRUE(late.T_world_board(0, f).isApprox(plain.T_world_board(0, f), 0));
    if (f == 10 || f == o.frames - 1) {  // noise-free images: the delayed frame, to the bit
      const cv::Mat image = late.render(camera, f);
      EXPECT_EQ(compare(image, plain.render(camera, shown)).max, 0) << "frame " << f;
      // ... and not the undelayed one (the board moved in between).
      EXPECT_GT(compare(image, plain.render(camera, f)).count, 100) << "frame " << f;
      ++image_checks;
    }
  }
  EXPECT_EQ(image_checks, 2);
  // The last frame is a floor frame for the rig, not for the late camera.
  EXPECT_TRUE(late.isFloorFrame(o.frames - 1));
  EXPECT_FALSE(late.showsFloorBoard(camera, o.frames - 1));
}

Pose bumpOf(double dx_m, double angle_deg, const Eigen::Vector3d& axis) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(angle_deg * M_PI / 180.0, axis.normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(dx_m, 0, 0);
  return T;
}

// A knocked camera: the true rig holds T_world_cam * bump and the truth projects through it.
TEST(RigCapture, BumpMovesTheTruePose) {
  RigCaptureOptions o = smallOptions();
  const RigCapture plain(o);
  const Pose bump = bumpOf(0.02, 1.0, Eigen::Vector3d(0.2, 1.0, 0.1));
  o.bump["witness01"] = bump;
  const RigCapture knocked(o);
  const Rig layout = studioRig(o.rig, StudioConfig{}.take_duration_s, false);
  EXPECT_TRUE(knocked.rig().cameras[0].T_world_cam.isApprox(layout.cameras[0].T_world_cam * bump, 1e-12));
  EXPECT_TRUE(knocked.rig().cameras[1].T_world_cam.isApprox(layout.cameras[1].T_world_cam, 0));
  const int frame = visibleFrame(plain, 0, 20);
  ASSERT_GE(frame, 0);
  const RigCamera& rc = knocked.rig().cameras[0];
  std::map<int, Eigen::Vector3d> p_board;
  for (const BoardPoint& bp : boardPoints(knocked.board())) p_board[bp.id] = bp.p_board;
  std::map<int, Eigen::Vector2d> before;
  for (const BoardObservation& b : plain.truth(0, frame)) before[b.id] = b.px;
  double shift = 0;
  int n = 0;
  for (const BoardObservation& b : knocked.truth(0, frame)) {
    const auto px = rc.camera.project(rc.T_world_cam.inverse() * knocked.T_world_board(0, frame) *
                                      p_board.at(b.id));
    ASSERT_TRUE(px.has_value());
    EXPECT_LT((*px - b.px).norm(), 1e-9);
    if (before.count(b.id)) shift += (b.px - before.at(b.id)).norm(), ++n;
  }
  ASSERT_GT(n, 10);
  // 1 degree at fx ~ 370 px (480 px wide) moves the image by ~6 px.
  std::printf("bump 2 cm, 1 degree: truth points moved %.2f px on average\n", shift / n);
  EXPECT_GT(shift / n, 3.0);
}

// What a detector finds in the rendered frames lies where the truth says, to a tenth of a
// pixel, for a bumped camera and a late one (so images and truth agree on both). Witness frames:
// most of the board in view, seen within 50 degrees of face on (grazing views of the 6 x 6
// AprilGrid do not decode; that is the detector's business, not the renderer's).
TEST(RigCapture, DetectedBoardMatchesTruthWithinATenthOfAPixel) {
  RigCaptureOptions o;  // full-size witnesses, default rig, AprilGrid
  o.noise_sigma = 2.0;
  o.bump["witness01"] = bumpOf(0.01, 0.5, Eigen::Vector3d(1, 0, 0));
  o.delay_frames["witness02"] = 5;
  const RigCapture capture(o);
  const size_t n_points = boardPoints(capture.board()).size();
  std::vector<double> errors;
  int detected_total = 0, truth_total = 0;
  for (int camera : {0, 1}) {
    int views = 0;
    const size_t min_points = n_points * 6 / 10;
    const double min_facing = std::cos(50.0 * M_PI / 180.0);
    for (int f = visibleFrame(capture, camera, min_points, 0, min_facing); f >= 0 && views < 3;
         f = visibleFrame(capture, camera, min_points, f + 17, min_facing)) {
      const cv::Mat image = capture.render(camera, f);
      const calib::ViewObservations view = calib::detectBoard(image, capture.board());
      std::map<int, Eigen::Vector2d> truth;
      for (const BoardObservation& b : capture.truth(camera, f)) truth[b.id] = b.px;
      int matched = 0;
      for (const calib::Observation& p : view.points) {
        if (!truth.count(p.id)) continue;
        errors.push_back((p.px - truth.at(p.id)).norm());
        ++matched;
      }
      std::printf("%s frame %d: %d of %zu truth points detected\n",
                  capture.rig().cameras[camera].camera.name.c_str(), f, matched, truth.size());
      detected_total += matched;
      truth_total += static_cast<int>(truth.size());
      ++views;
    }
    EXPECT_EQ(views, 3) << "camera " << camera;
  }
  ASSERT_FALSE(errors.empty());
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2];
  const double p95 = errors[errors.size() * 95 / 100];
  std::printf("detection vs truth over %zu points: median %.3f px, 95th percentile %.3f px\n",
              errors.size(), median, p95);
  EXPECT_LT(median, 0.1);
  EXPECT_LT(p95, 0.5);
  EXPECT_GE(detected_total, truth_total / 2);
}

TEST(RigCapture, FloorFramesComeLastUnlessTurnedOff) {
  RigCaptureOptions o = smallOptions();
  const RigCapture with_floor(o);
  for (int f = 0; f < o.frames; ++f) EXPECT_EQ(with_floor.isFloorFrame(f), f >= o.frames - 3);
  EXPECT_TRUE(with_floor.T_world_board(0, o.frames - 1).isApprox(floorBoardPose(), 0));
  o.floor_frames = false;
  const RigCapture waving(o);
  for (int f = 0; f < o.frames; ++f) {
    EXPECT_FALSE(waving.isFloorFrame(f));
    EXPECT_TRUE(waving.T_world_board(0, f).isApprox(
        rigWavedBoardPose(waving.board(), f, o.frames, o.board_seed), 0));
  }
  // Well above the floor in the frames that used to lie on it.
  EXPECT_GT(waving.T_world_board(0, o.frames - 1).translation().z(), 0.3);
}

TEST(RigCapture, FloorOnlyShowsTheStillFloorBoardInEveryFrame) {
  RigCaptureOptions o = smallOptions();
  o.frames = 2;
  o.floor_only = true;
  const RigCapture still(o);
  for (int f = 0; f < o.frames; ++f) {
    EXPECT_TRUE(still.isFloorFrame(f));
    EXPECT_TRUE(still.showsFloorBoard(0, f));
    EXPECT_TRUE(still.T_world_board(0, f).isApprox(floorBoardPose(), 0));
  }
  o.floor_frames = false;
  try {
    const RigCapture contradiction(o);
    ADD_FAILURE() << "floor_only with floor_frames = false accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "floor_only") << e.what();
  }
}

TEST(RigCapture, BadOptionsNameTheCameraOrField) {
  auto errorOf = [](const RigCaptureOptions& o) -> ErrorContext {
    try {
      RigCapture capture(o);
    } catch (const Error& e) {
      return e.context();
    }
    ErrorContext accepted;
    accepted.field = "(accepted)";
    return accepted;
  };
  RigCaptureOptions o = smallOptions();
  EXPECT_EQ(errorOf(o).field, "(accepted)");
  o.delay_frames["witness09"] = 2;  // 3 witnesses only
  EXPECT_EQ(errorOf(o).field, "delay_frames");
  EXPECT_EQ(errorOf(o).camera, "witness09");
  o = smallOptions();
  o.bump["main"] = Pose::Identity();  // no main camera in this rig
  EXPECT_EQ(errorOf(o).field, "bump");
  EXPECT_EQ(errorOf(o).camera, "main");
  o = smallOptions();
  o.gain["witness01"] = 0.0;
  EXPECT_EQ(errorOf(o).field, "gain");
  o = smallOptions();
  o.frames = 0;
  EXPECT_EQ(errorOf(o).field, "frames");
  o = smallOptions();
  o.samples_per_pixel = 2;
  EXPECT_EQ(errorOf(o).field, "samples_per_pixel");

  const RigCapture capture(smallOptions());
  try {
    capture.render(1, 30);
    ADD_FAILURE() << "frame 30 of 30 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "witness02");
    EXPECT_EQ(e.context().frame, 30);
  }
  EXPECT_THROW(capture.truth(3, 0), Error);
  EXPECT_THROW(capture.T_world_board(-1, 0), Error);
}

}  // namespace
}  // namespace previz::synth
