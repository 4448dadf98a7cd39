// A calibrated rig placed on the floor board (multicam/floor_world.h): the true studio rig moved
// to an arbitrary frame (as another tool would have written it) comes back to previz's world
// from the floor board's projections alone (0.2 px noise per coordinate, the rig board lying
// still on the floor, observation level: tests/multicam/rig_calib_fixtures.h); with fit_scale,
// the same rig at COLMAP's arbitrary scale through previz's own COLMAP export and import. Figures:
//   build/tests/multicam/multicam_tests --gtest_filter='FloorWorld*'
#include "multicam/floor_world.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/rig_import.h"
#include "scratch.h"
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

// Two still floor frames, every camera's view of the board with noise_px per coordinate.
testing::ProjectedCapture floorCapture(double noise_px = 0.2) {
  ProjectedCaptureOptions o;
  o.frames = 2;
  o.floor_only = true;
  o.noise_px = noise_px;
  return projectedCapture(o);
}

// COLMAP's reconstruction of the studio: the true rig moved to the other frame and its positions
// scaled by `scale` (a reconstruction without metric scale), written by previz's COLMAP export
// (cameras.txt, images.txt) and imported back.
RigImport colmapImport(const Rig& truth, double scale, const std::string& name) {
  Rig rig = moved(truth);
  for (RigCamera& rc : rig.cameras) rc.T_world_cam.translation() *= scale;
  const std::filesystem::path dir = test::scratchDir("multicam", "floor_world_" + name);
  exportColmap(rig, dir);
  return importColmap(dir, ImportOptions{});
}

// The cameras' worst centre (m) and rotation (deg) against the truth, matched by name.
std::pair<double, double> worstCamera(const Rig& placed, const Rig& truth) {
  double dp = 0, dr = 0;
  for (const RigCamera& rc : truth.cameras) {
    const Pose& p = placed.at(rc.camera.name).T_world_cam;
    dp = std::max(dp, translationDistance(p, rc.T_world_cam));
    dr = std::max(dr, rotationDistance(p, rc.T_world_cam) * 180 / M_PI);
  }
  return {dp, dr};
}

bool has(const std::vector<std::string>& lines, const std::string& text) {
  const auto contains = [&](const std::string& l) { return l.find(text) != std::string::npos; };
  return std::any_of(lines.begin(), lines.end(), contains);
}

// Two still floor frames, 0.2 px noise: the board pose rests on every camera's view of it, so
// the whole rig moves as one. Measured 0.65 mm / 0.0073 deg at worst over the 9 cameras (the
// board's pose error in the rig, shared by all, seen from 3-6 m; RMS 0.28 px = the noise).
// Bound: 2 mm and 0.05 deg, the rig solve's (rig_calib_test.cpp).
TEST(FloorWorld, MovedRigComesBackToTheTruthFromTheFloorBoard) {
  const auto capture = floorCapture();
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
  const auto capture = floorCapture();
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
  auto capture = floorCapture();
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

// A COLMAP rig at scale 0.137 in an arbitrary frame, placed on the floor board with fit_scale:
// the scale from the closed form (each view's PnP against its camera's centre), refined with the
// board pose in the bundle. Measured: noise 0, exact (scale off by 4e-16); 0.2 px per
// coordinate, scale off by 7.3e-5 (its sigma 3.8e-5; over 30 noise seeds the error's RMS is 1.09
// sigma, the closed form's alone 5.2e-5), worst camera 0.74 mm, 0.0071 deg (the metric rig's:
// 0.65 mm, 0.0073 deg; 1e-4 of scale is 0.5 mm at 5 m). Bounds: scale 2.5e-4 and 4 of its
// sigmas, the closed form 1 %, the floor placement's 2 mm and 0.05 deg.
TEST(FloorWorld, ColmapRigOfUnknownScaleComesBackMetricWithFitScale) {
  constexpr double kColmapScale = 0.137;
  for (const double noise_px : {0.0, 0.2}) {
    const auto capture = floorCapture(noise_px);
    RigImport imported = colmapImport(capture.truth, kColmapScale, "colmap");
    FloorPlacementOptions options;
    options.fit_scale = true;
    const FloorPlacement p = placeImportOnFloor(imported, capture.obs, "take/floor.json", ImportOptions{}, options);
    const double scale_error = p.scale * kColmapScale - 1.0;
    const auto [dp, dr] = worstCamera(imported.rig, capture.truth);
    std::printf("  noise %.1f px: scale %.6f (closed form %.6f), off by %.2g (sigma %.2g); worst camera %.4f mm, "
                "%.5f deg; RMS %.3f px\n",
                noise_px, p.scale, p.start_scale, scale_error, p.implied_scale_sigma * kColmapScale, dp * 1e3, dr,
                p.rms_px);
    EXPECT_LT(std::abs(scale_error), noise_px > 0 ? 2.5e-4 : 1e-9);
    if (noise_px > 0) {
      EXPECT_LT(std::abs(scale_error), 4 * p.implied_scale_sigma * kColmapScale);
    }
    EXPECT_LT(std::abs(p.start_scale * kColmapScale - 1.0), 0.01);  // the start: within 1 %
    EXPECT_GT(p.implied_scale_sigma, 0.0);
    EXPECT_EQ(p.implied_scale, p.scale);
    EXPECT_LE(dp, 0.002);
    EXPECT_LE(dr, 0.05);
    const std::string report = imported.report.fullReport();
    EXPECT_NE(report.find("scaled by 7."), std::string::npos) << report;  // 1 / 0.137 = 7.2993
    EXPECT_FALSE(has(imported.report.warnings, "scale")) << report;
  }
}

// Without fit_scale the rig's scale is kept: the placement is off, and the report says by how
// much the board disagrees and what to do; a metric rig is checked and not warned about.
TEST(FloorWorld, AScaleTheBoardDisagreesWithIsWarnedAboutWithoutFitScale) {
  const auto capture = floorCapture();
  RigImport colmap = colmapImport(capture.truth, 0.137, "unscaled");
  const FloorPlacement p = placeImportOnFloor(colmap, capture.obs, "take/floor.json", ImportOptions{});
  EXPECT_EQ(p.scale, 1.0);
  EXPECT_NEAR(p.implied_scale * 0.137, 1.0, 2.5e-4);
  EXPECT_TRUE(has(colmap.report.warnings, "the floor board implies a scale of 7.")) << colmap.report.fullReport();
  EXPECT_TRUE(has(colmap.report.warnings, "--fit-scale")) << colmap.report.fullReport();

  RigImport metric = colmapImport(capture.truth, 1.0, "metric");
  const FloorPlacement m = placeImportOnFloor(metric, capture.obs, "take/floor.json", ImportOptions{});
  EXPECT_NEAR(m.implied_scale, 1.0, 2.5e-4);
  EXPECT_FALSE(has(metric.report.warnings, "scale")) << metric.report.fullReport();
  EXPECT_TRUE(has(metric.report.assumptions, "the board implies a scale of 1.0")) << metric.report.fullReport();
  const auto [dp, dr] = worstCamera(metric.rig, capture.truth);
  EXPECT_LE(dp, 0.002);
  EXPECT_LE(dr, 0.05);
}

// One camera seeing the board, or cameras all at one place, cannot fix a scale: an Error on the
// fit_scale field with fit_scale, an unchecked scale (implied 0) without.
TEST(FloorWorld, AScaleOneCameraPlaceCannotFixIsAnErrorOnFitScale) {
  auto capture = floorCapture();
  FloorPlacementOptions fit;
  fit.fit_scale = true;
  const auto expectFitScaleError = [&](const Rig& rig, const RigObservations& obs, const std::string& text) {
    try {
      placeRigOnFloor(rig, obs, fit);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, "fit_scale") << e.what();
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
    }
  };
  RigObservations one = capture.obs;
  for (size_t c = 1; c < one.cameras.size(); ++c) one.cameras[c].frames.clear();
  expectFitScaleError(capture.truth, one, "needs 2 or more cameras");
  EXPECT_EQ(placeRigOnFloor(capture.truth, one).implied_scale, 0.0);

  Rig head = capture.truth;  // every camera on one tripod head
  for (RigCamera& rc : head.cameras) rc.T_world_cam.translation() = capture.truth.cameras[0].T_world_cam.translation();
  expectFitScaleError(head, capture.obs, "at one place");
}

}  // namespace
}  // namespace previz::multicam
