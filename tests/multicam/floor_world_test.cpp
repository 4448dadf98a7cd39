// A calibrated rig placed on the floor board (multicam/floor_world.h): the true studio rig moved
// to an arbitrary frame (as another tool would have written it) comes back to previz's world
// from the floor board's projections alone (0.2 px noise per coordinate, the rig board lying
// still on the floor, observation level: tests/multicam/rig_calib_fixtures.h). Figures:
//   build/tests/multicam/multicam_tests --gtest_filter='FloorWorld*'
#include "multicam/floor_world.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include <Eigen/Geometry>

#include "core/error.h"
#include "tests/multicam/rig_calib_fixtures.h"

namespace previz::multicam {
namespace {

using testing::ProjectedCaptureOptions;
using testing::projectedCapture;

// The other tool's frame: T_file_world, a skew turn and a shift of metres.
Pose fileFromWorld() {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(12.5, -4.25, 7.75);
  return T;
}

Rig moved(const Rig& truth) {
  Rig rig = truth;
  for (RigCamera& rc : rig.cameras) rc.T_world_cam = fileFromWorld() * rc.T_world_cam;
  rig.world_frame = "another tool's";
  return rig;
}

// Two still floor frames, 0.2 px noise: the board pose rests on every camera's view of it, so
// the whole rig moves as one. Measured 0.65 mm / 0.0073 deg at worst over the 9 cameras (the
// board's pose error in the rig, shared by all, seen from 3-6 m; RMS 0.28 px = the noise).
// Bound: 2 mm and 0.05 deg, the rig solve's (rig_calib_test.cpp).
TEST(FloorWorld, MovedRigComesBackToTheTruthFromTheFloorBoard) {
  ProjectedCaptureOptions o;
  o.frames = 2;
  o.floor_only = true;
  const auto capture = projectedCapture(o);
  const Rig rig = moved(capture.truth);
  const FloorPlacement p = placeRigOnFloor(rig, capture.obs);
  double dp = 0, dr = 0;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    const Pose placed = p.T_world_rig * rig.cameras[c].T_world_cam;
    const Pose& truth = capture.truth.cameras[c].T_world_cam;
    dp = std::max(dp, translationDistance(placed, truth));
    dr = std::max(dr, rotationDistance(placed, truth) * 180 / M_PI);
    EXPECT_GT(p.cameras[c].views, 0) << p.cameras[c].camera;
    EXPECT_LT(p.cameras[c].rms_px, 0.4) << p.cameras[c].camera;  // 2 x the noise per coordinate
  }
  std::printf("  floor placement: worst camera %.4f mm, %.5f deg; %d points, RMS %.3f px, %d rejected\n",
              dp * 1e3, dr, p.points, p.rms_px, p.rejected);
  EXPECT_LE(dp, 0.002);
  EXPECT_LE(dr, 0.05);
}

// A camera whose pose in the file is wrong (turned 1 degree) disagrees with the board the others
// see: its RMS says so, and the placement, resting on all, stays within a few mm.
TEST(FloorWorld, ACameraWrongInTheFileStandsOutByItsResiduals) {
  ProjectedCaptureOptions o;
  o.frames = 2;
  o.floor_only = true;
  const auto capture = projectedCapture(o);
  Rig rig = moved(capture.truth);
  Pose& knocked = rig.at("witness03").T_world_cam;
  knocked.linear() = knocked.linear() * Eigen::AngleAxisd(M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const FloorPlacement p = placeRigOnFloor(rig, capture.obs);
  for (const FloorPlacementCamera& c : p.cameras) {
    if (c.camera == "witness03") EXPECT_GT(c.rms_px, 5.0) << c.camera;
    else EXPECT_LT(c.rms_px, 1.0) << c.camera;
  }
}

TEST(FloorWorld, NoFloorFramesOrNoCameraSeeingTheBoardIsAnErrorOnTheFloorField) {
  ProjectedCaptureOptions o;
  o.frames = 2;
  o.floor_only = true;
  auto capture = projectedCapture(o);
  for (CameraDetections& c : capture.obs.cameras) c.frames.clear();
  for (const bool has_floor : {true, false}) {
    capture.obs.has_floor = has_floor;
    try {
      placeRigOnFloor(capture.truth, capture.obs);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, "floor") << e.what();
    }
  }
}

}  // namespace
}  // namespace previz::multicam
