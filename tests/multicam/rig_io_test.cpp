// Rig outputs: per-camera OpenCV YAML read back by cv::FileStorage (intrinsics and world-to-
// camera extrinsics), and the report JSON figures.
#include "multicam/rig_io.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/camera_io.h"
#include "datasets/rigs.h"
#include "scratch.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

TEST(RigYaml, OpenCvReadsBackIntrinsicsAndWorldToCameraExtrinsics) {
  const fs::path dir = test::scratchDir("multicam_rig_io", "yaml");
  synth::StudioRigOptions o;
  o.witness_cameras = 3;
  o.fisheye_witnesses = 1;  // a fisheye's file is cv::fisheye's (distortion_model equidistant, 4 x 1 D)
  const Rig rig = synth::studioRig(o, 10.0, false);
  ASSERT_FALSE(rig.cameras.front().camera.dist.isBrown());
  const std::vector<fs::path> files = writeRigYaml(rig, dir);
  ASSERT_EQ(files.size(), rig.cameras.size());
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    const RigCamera& rc = rig.cameras[i];
    SCOPED_TRACE(rc.camera.name);
    EXPECT_EQ(files[i], dir / (rc.camera.name + ".yaml"));
    cv::FileStorage fs(files[i].string(), cv::FileStorage::READ);
    ASSERT_TRUE(fs.isOpened());
    cv::Mat K, D, R, t, rvec;
    int w = 0, h = 0;
    fs["image_width"] >> w;
    fs["image_height"] >> h;
    fs["camera_matrix"] >> K;
    fs["distortion_coefficients"] >> D;
    fs["R"] >> R;
    fs["t"] >> t;
    fs["rvec"] >> rvec;
    EXPECT_EQ(w, rc.camera.width);
    EXPECT_EQ(h, rc.camera.height);
    EXPECT_DOUBLE_EQ(K.at<double>(0, 0), rc.camera.fx);
    EXPECT_DOUBLE_EQ(K.at<double>(1, 2), rc.camera.cy);
    EXPECT_DOUBLE_EQ(D.at<double>(0), rc.camera.dist.k1);
    // A world point goes to the camera through R, t: the camera centre to the origin, and a
    // point ahead of the camera projects where previz projects it.
    const Eigen::Vector3d centre = rc.T_world_cam.translation();
    cv::Mat c_world = (cv::Mat_<double>(3, 1) << centre.x(), centre.y(), centre.z());
    EXPECT_LT(cv::norm(R * c_world + t), 1e-9);
    cv::Mat R_from_rvec;
    cv::Rodrigues(rvec, R_from_rvec);
    EXPECT_LT(cv::norm(R_from_rvec - R), 1e-12);
    const Eigen::Vector3d p_world = synth::witnessAimPoint();
    std::vector<cv::Point2d> px;
    const std::vector<cv::Point3d> points{{p_world.x(), p_world.y(), p_world.z()}};
    std::string model;
    fs["distortion_model"] >> model;
    if (rc.camera.dist.isBrown()) {
      EXPECT_EQ(model, "");
      EXPECT_EQ(D.rows, 5);
      cv::projectPoints(points, rvec, t, K, D, px);
    } else {
      EXPECT_EQ(model, "equidistant");
      ASSERT_EQ(D.rows, 4);
      EXPECT_DOUBLE_EQ(D.at<double>(3), rc.camera.dist.k4);
      cv::fisheye::projectPoints(points, px, rvec, t, K, D);
    }
    const Eigen::Vector2d expected = *rc.camera.project(rc.T_world_cam.inverse() * p_world);
    EXPECT_NEAR(px[0].x, expected.x(), 1e-6);
    EXPECT_NEAR(px[0].y, expected.y(), 1e-6);
    // previz's own OpenCV reader takes the same file.
    const Camera back = readOpenCvCamera(files[i], rc.camera.name);
    EXPECT_DOUBLE_EQ(back.fx, rc.camera.fx);
    EXPECT_DOUBLE_EQ(back.dist.k2, rc.camera.dist.k2);
    EXPECT_TRUE(back.dist == rc.camera.dist);
  }
}

TEST(RigReportJson, CarriesPerCameraFiguresAndPositions) {
  synth::StudioRigOptions o;
  o.witness_cameras = 2;
  o.with_main = false;
  RigCalibResult result;
  result.rig = synth::studioRig(o, 10.0, false);
  for (const RigCamera& rc : result.rig.cameras) {
    CameraCalibReport r;
    r.camera = rc.camera.name;
    r.views = 10;
    r.rms_px = 0.25;
    r.sigma_position_m = 0.001;
    result.cameras.push_back(r);
  }
  result.spanning_tree.push_back({"witness01", "witness02", 17});
  result.rms_px = 0.25;
  const nlohmann::json j = reportToJson(result);
  ASSERT_EQ(j.at("cameras").size(), 2u);
  EXPECT_EQ(j.at("cameras")[1].at("camera"), "witness02");
  EXPECT_DOUBLE_EQ(j.at("cameras")[0].at("position_m")[2].get<double>(),
                   result.rig.cameras[0].T_world_cam.translation().z());
  EXPECT_EQ(j.at("spanning_tree")[0].at("shared_frames"), 17);

  SyncReport sync;
  sync.ok = false;
  CameraSync late;
  late.camera = "witness02";
  late.offset_frames = 2;
  late.in_sync = false;
  sync.cameras.push_back(late);
  const nlohmann::json js = syncToJson(sync);
  EXPECT_EQ(js.at("cameras")[0].at("offset_frames"), 2);
  EXPECT_FALSE(js.at("ok").get<bool>());

  RigCheckResult check;
  check.ok = false;
  RigCheckCamera bumped;
  bumped.camera = "witness01";
  bumped.views = 10;
  bumped.rms_px = 3.5;
  bumped.flagged = true;
  bumped.reason = "rms 3.5 px > 1 px";
  check.cameras.push_back(bumped);
  const nlohmann::json jc = checkToJson(check);
  EXPECT_TRUE(jc.at("cameras")[0].at("flagged").get<bool>());
  EXPECT_DOUBLE_EQ(jc.at("cameras")[0].at("rms_px").get<double>(), 3.5);
}

}  // namespace
}  // namespace previz::multicam
