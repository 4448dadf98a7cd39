// Real data for the joint rig solve (multicam/rig_calib.h): OpenCV's stereo sample
// (../shared/data/opencv-chessboard), two webcams side by side, 13 synchronised pairs of a 9 x 6
// inner-corner chessboard, square 1 unit (the baseline comes out in squares). Each camera's
// intrinsics come from its own 13 images (calib), then the two-camera rig is solved with them
// held, beside cv::stereoCalibrate on the very same detections and intrinsics
// (CALIB_FIX_INTRINSIC). There is no ground truth: OpenCV's answer is the reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calib/detect.h"
#include "calib/intrinsics.h"
#include "core/board.h"
#include "core/io.h"
#include "core/rig_import.h"
#include "multicam/rig_calib.h"
#include "tests/real_data.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;
const fs::path kDir = fs::path(PREVIZ_SHARED_DATA) / "opencv-chessboard";

// Image number -> detections, for "left" or "right".
std::map<int, calib::ViewObservations> detectSide(const std::string& side, const BoardSpec& board) {
  std::map<int, calib::ViewObservations> views;
  if (!fs::is_directory(kDir)) return views;
  for (const auto& e : fs::directory_iterator(kDir)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(side, 0) != 0 || e.path().extension() != ".jpg") continue;
    const int number = std::stoi(name.substr(side.size(), 2));
    const cv::Mat image = readImage(e.path(), cv::IMREAD_GRAYSCALE);
    calib::ViewObservations v = calib::detectBoard(image, board, {}, name);
    v.image_size = image.size();
    views[number] = v;
  }
  return views;
}

cv::Mat distCoeffs(const Camera& c) {
  return (cv::Mat_<double>(1, 5) << c.dist.k1, c.dist.k2, c.dist.p1, c.dist.p2, c.dist.k3);
}

TEST(RigCalibReal, StereoPairAgreesWithOpenCvStereoCalibrate) {
  const BoardSpec board = previz::test::opencvSampleBoard();
  std::map<std::string, std::map<int, calib::ViewObservations>> sides;
  for (const char* side : {"left", "right"}) sides[side] = detectSide(side, board);
  ASSERT_EQ(sides["left"].size(), 13u) << "real data missing: " << kDir.string() << " (../shared/data, see its README)";
  ASSERT_EQ(sides["right"].size(), 13u) << kDir.string();

  RigObservations obs;
  obs.board = board;
  obs.frame_count = 15;  // image numbers 1..14 are the frames
  Rig initial;
  for (const std::string side : {"left", "right"}) {
    std::vector<calib::ViewObservations> views;
    for (const auto& [number, v] : sides[side]) views.push_back(v);
    const calib::IntrinsicsResult intr = calib::calibrateIntrinsics(views, board);
    RigCamera rc;
    rc.camera = intr.camera;
    rc.camera.name = side;
    initial.cameras.push_back(rc);
    CameraDetections cd;
    cd.camera = side;
    cd.image_size = views.front().image_size;
    for (const auto& [number, v] : sides[side])
      if (v.found()) cd.frames[number] = v.points;
    obs.cameras.push_back(cd);
  }
  RigCalibOptions options;
  options.reference_camera = "left";
  const RigCalibResult ours = calibrateRig(obs, initial, options);
  const Pose T_left_right = ours.rig.at("left").T_world_cam.inverse() * ours.rig.at("right").T_world_cam;

  // OpenCV on the pairs where both cameras found the board, the same points in the same order.
  std::map<int, Eigen::Vector3d> points;
  for (const BoardPoint& p : boardPoints(board)) points[p.id] = p.p_board;
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> left_px, right_px;
  for (const auto& [number, l] : sides["left"]) {
    const auto r = sides["right"].find(number);
    if (!l.found() || r == sides["right"].end() || !r->second.found()) continue;
    std::map<int, Eigen::Vector2d> right_by_id;
    for (const calib::Observation& o : r->second.points) right_by_id[o.id] = o.px;
    object.emplace_back();
    left_px.emplace_back();
    right_px.emplace_back();
    for (const calib::Observation& o : l.points) {
      const auto q = right_by_id.find(o.id);
      if (q == right_by_id.end()) continue;
      const Eigen::Vector3d& p = points.at(o.id);
      object.back().emplace_back(p.x(), p.y(), p.z());
      left_px.back().emplace_back(o.px.x(), o.px.y());
      right_px.back().emplace_back(q->second.x(), q->second.y());
    }
  }
  const Camera& cl = initial.at("left").camera;
  const Camera& cr = initial.at("right").camera;
  cv::Mat K1, K2, D1 = distCoeffs(cl), D2 = distCoeffs(cr), R, T, E, F;
  cv::eigen2cv(Eigen::Matrix3d(cl.K()), K1);
  cv::eigen2cv(Eigen::Matrix3d(cr.K()), K2);
  const double cv_rms = cv::stereoCalibrate(object, left_px, right_px, K1, D1, K2, D2,
                                            cv::Size(cl.width, cl.height), R, T, E, F, cv::CALIB_FIX_INTRINSIC);
  // OpenCV's R, T take left-camera points to right-camera points: T_right_left.
  Eigen::Matrix3d R_rl;
  Eigen::Vector3d t_rl;
  cv::cv2eigen(R, R_rl);
  cv::cv2eigen(T, t_rl);
  Pose T_right_left = Pose::Identity();
  T_right_left.linear() = R_rl;
  T_right_left.translation() = t_rl;
  const Pose cv_left_right = T_right_left.inverse();

  const double base_ours = T_left_right.translation().norm(), base_cv = cv_left_right.translation().norm();
  const double dt = (T_left_right.translation() - cv_left_right.translation()).norm();
  const double dR_deg =
      Eigen::AngleAxisd(T_left_right.linear().transpose() * cv_left_right.linear()).angle() * 180.0 / M_PI;
  const CameraCalibReport& right = ours.cameras[1];
  std::printf("\nReal stereo pair (%zu pairs): rig solve vs cv::stereoCalibrate, same detections and intrinsics\n",
              object.size());
  std::printf("  %-8s %10s %28s %9s\n", "", "baseline", "right camera centre (left)", "RMS px");
  std::printf("  %-8s %10.4f %9.4f %9.4f %9.4f %9.4f\n", "ours", base_ours, T_left_right.translation().x(),
              T_left_right.translation().y(), T_left_right.translation().z(), ours.rms_px);
  std::printf("  %-8s %10.4f %9.4f %9.4f %9.4f %9.4f\n", "opencv", base_cv, cv_left_right.translation().x(),
              cv_left_right.translation().y(), cv_left_right.translation().z(), cv_rms);
  std::printf("  difference: centre %.4f squares (our 1-sigma %.4f), rotation %.4f deg (our 1-sigma %.4f); "
              "%d of %d points rejected\n",
              dt, right.sigma_position_m, dR_deg, right.sigma_rotation_deg, ours.rejected, ours.residuals + ours.rejected);
  ASSERT_EQ(ours.rig.cameras.size(), 2u);
  // Both minimise the same reprojection error here (no point rejected by ours): measured equal to
  // the printed digits, so half a sigma is a wide margin.
  EXPECT_LE(dt, 0.5 * right.sigma_position_m);
  EXPECT_LE(dR_deg, 0.5 * right.sigma_rotation_deg);
  EXPECT_LE(ours.rms_px, cv_rms + 0.001);

  // OpenCV's answer as its stereo_calib sample writes it (intrinsics.yml: M1 D1 M2 D2;
  // extrinsics.yml: R T), imported as another tool's rig: the same two-camera rig as our solve.
  const fs::path dir = fs::path(PREVIZ_TEST_TMP) / "rig_real_stereo";
  fs::create_directories(dir);
  {
    cv::FileStorage intr((dir / "intrinsics.yml").string(), cv::FileStorage::WRITE);
    intr << "M1" << K1 << "D1" << D1 << "M2" << K2 << "D2" << D2;
    cv::FileStorage extr((dir / "extrinsics.yml").string(), cv::FileStorage::WRITE);
    extr << "R" << R << "T" << T;
  }
  ImportOptions io;
  io.width = cl.width;
  io.height = cl.height;
  const RigImport imported = importOpenCv({dir / "intrinsics.yml", dir / "extrinsics.yml"}, io);
  ASSERT_EQ(imported.rig.cameras.size(), 2u);
  const Pose imported_left_right =
      imported.rig.cameras[0].T_world_cam.inverse() * imported.rig.cameras[1].T_world_cam;
  const double dt_import = (T_left_right.translation() - imported_left_right.translation()).norm();
  const double dR_import = Eigen::AngleAxisd(T_left_right.linear().transpose() * imported_left_right.linear()).angle() *
                           180.0 / M_PI;
  std::printf("  OpenCV's files imported: centre %.4f squares from ours, rotation %.4f deg; fx %.3f / %.3f\n",
              dt_import, dR_import, imported.rig.cameras[1].camera.fx, cr.fx);
  EXPECT_LE(dt_import, 0.5 * right.sigma_position_m);
  EXPECT_LE(dR_import, 0.5 * right.sigma_rotation_deg);
  EXPECT_NEAR(imported.rig.cameras[1].camera.fx, cr.fx, 1e-9 * cr.fx);
  EXPECT_NEAR(imported.rig.cameras[1].camera.dist.k1, cr.dist.k1, 1e-12);
}

}  // namespace
}  // namespace previz::multicam
