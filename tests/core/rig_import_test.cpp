// Other tools' rigs in and out (core/rig_import.h): every format round-trips a 3-camera rig with
// real rotations; OpenCV's rvec/tvec, stereoCalibrate's R/T, Kalibr's chain and COLMAP's
// quaternions land where those tools put them; sizes, names, units, axes and the rotation rule;
// the real Middlebury temple and Oxford dino rows. Figures: run
//   build/tests/core/core_tests --gtest_filter='RigImport*'
#include "core/rig_import.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "scratch.h"

namespace fs = std::filesystem;

namespace previz {
namespace {

fs::path tmpDir(const std::string& name) { return test::scratchDir("core", "rig_import_" + name); }

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

bool anyContains(const std::vector<std::string>& lines, const std::string& part) {
  for (const std::string& l : lines)
    if (contains(l, part)) return true;
  return false;
}

// Three witnesses around a stage, each rolled a little about its axis (so no rotation is a
// plain look-at), metres; lens terms as the format can carry them.
struct LensTerms {
  bool skew = true;
  bool k3 = true;
  bool distortion = true;
};

LensTerms without(bool skew, bool k3, bool distortion) {
  LensTerms t;
  t.skew = !skew;
  t.k3 = !k3;
  t.distortion = !distortion;
  return t;
}

Rig sampleRig(LensTerms terms = {}) {
  Rig rig;
  const Eigen::Vector3d eyes[3] = {{3.2, -1.1, 1.9}, {-0.7, 3.4, 2.6}, {-2.9, -2.2, 0.8}};
  for (int i = 0; i < 3; ++i) {
    RigCamera rc;
    Camera& c = rc.camera;
    c.name = "witness0" + std::to_string(i + 1);
    c.width = 1920 - 640 * (i == 2);
    c.height = 1080 - 360 * (i == 2);
    c.fx = 1412.3456789012345 + 37.1 * i;
    c.fy = 1409.8765432109876 + 35.3 * i;
    c.cx = 961.123456789 - 3.3 * i;
    c.cy = 538.987654321 + 2.2 * i;
    c.skew = terms.skew ? 0.25 * (i + 1) : 0.0;
    if (terms.distortion && i != 1)  // camera 2 without distortion (COLMAP: PINHOLE)
      c.dist = {-0.2345678901234 + 0.01 * i, 0.0876543210987, 0.000123456789, -0.000987654321,
                terms.k3 && i == 0 ? -0.0123456789 : 0.0};
    rc.T_world_cam = lookAt(eyes[i], {0.1, -0.2, 1.0});
    rc.T_world_cam.linear() = rc.T_world_cam.linear() * Eigen::AngleAxisd(0.05 + 0.11 * i, Eigen::Vector3d::UnitZ());
    rig.cameras.push_back(rc);
  }
  return rig;
}

struct RigDiff {
  double intrinsics = 0;   // max |difference| over fx fy cx cy skew k1 k2 p1 p2 k3
  double rotation = 0;     // max |difference| over R_world_cam's entries
  double translation = 0;  // max |difference| over the camera centres, metres
};

RigDiff compareRigs(const Rig& truth, const Rig& back, bool names = true) {
  RigDiff d;
  EXPECT_EQ(truth.cameras.size(), back.cameras.size());
  for (size_t i = 0; i < std::min(truth.cameras.size(), back.cameras.size()); ++i) {
    const Camera& a = truth.cameras[i].camera;
    const Camera& b = back.cameras[i].camera;
    if (names) {
      EXPECT_EQ(a.name, b.name);
    }
    EXPECT_EQ(a.width, b.width) << a.name;
    EXPECT_EQ(a.height, b.height) << a.name;
    EXPECT_EQ(a.dist.model, b.dist.model) << a.name;
    const double da[] = {a.fx - b.fx, a.fy - b.fy, a.cx - b.cx, a.cy - b.cy, a.skew - b.skew,
                         a.dist.k1 - b.dist.k1, a.dist.k2 - b.dist.k2, a.dist.p1 - b.dist.p1,
                         a.dist.p2 - b.dist.p2, a.dist.k3 - b.dist.k3, a.dist.k4 - b.dist.k4,
                         a.dist.k5 - b.dist.k5, a.dist.k6 - b.dist.k6};
    for (double x : da) d.intrinsics = std::max(d.intrinsics, std::abs(x));
    const Pose& Ta = truth.cameras[i].T_world_cam;
    const Pose& Tb = back.cameras[i].T_world_cam;
    d.rotation = std::max(d.rotation, (Ta.linear() - Tb.linear()).cwiseAbs().maxCoeff());
    d.translation = std::max(d.translation, (Ta.translation() - Tb.translation()).cwiseAbs().maxCoeff());
  }
  return d;
}

void expectRoundTrip(const char* format, const Rig& truth, const Rig& back, bool names = true) {
  const RigDiff d = compareRigs(truth, back, names);
  std::cout << "round trip " << format << ": max |d intrinsics| " << d.intrinsics << ", |d R| " << d.rotation
            << ", |d centre| " << d.translation << " m\n";
  EXPECT_LE(d.intrinsics, 1e-9) << format;
  EXPECT_LE(d.rotation, 1e-9) << format;
  EXPECT_LE(d.translation, 1e-9) << format;
}

ImportOptions sized(int w, int h) {
  ImportOptions o;
  o.width = w;
  o.height = h;
  return o;
}

cv::Mat cvMat(const Eigen::MatrixXd& M) {
  cv::Mat m(static_cast<int>(M.rows()), static_cast<int>(M.cols()), CV_64F);
  for (int r = 0; r < m.rows; ++r)
    for (int c = 0; c < m.cols; ++c) m.at<double>(r, c) = M(r, c);
  return m;
}

// ---------------------------------------------------------------------------------------------
// Round trips: import(export(rig)) == rig to 1e-9, poses included.

TEST(RigImport, OpenCvExportImportRoundTripsEveryIntrinsicAndPose) {
  const fs::path dir = tmpDir("opencv_roundtrip");
  const Rig truth = sampleRig();
  const std::vector<fs::path> files = exportOpenCv(truth, dir);
  ASSERT_EQ(files.size(), 3u);
  EXPECT_EQ(files[0], dir / "witness01.yaml");
  const RigImport back = importOpenCv(files, {});
  expectRoundTrip("OpenCV YAML (rvec/tvec)", truth, back.rig);
  EXPECT_TRUE(back.report.warnings.empty()) << back.report.fullReport();
  // What we write is what OpenCV reads: rvec/tvec are the camera's world -> camera pose.
  cv::FileStorage store(files[1].string(), cv::FileStorage::READ);
  cv::Mat rvec, tvec, R;
  store["rvec"] >> rvec;
  store["tvec"] >> tvec;
  cv::Rodrigues(rvec, R);
  const Pose T_cam_world = truth.cameras[1].T_world_cam.inverse();
  for (int r = 0; r < 3; ++r) {
    EXPECT_NEAR(tvec.at<double>(r), T_cam_world.translation()(r), 1e-12);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(R.at<double>(r, c), T_cam_world.linear()(r, c), 1e-12);
  }
}

TEST(RigImport, KalibrExportImportRoundTripsEveryIntrinsicAndPose) {
  const fs::path path = tmpDir("kalibr_roundtrip") / "camchain.yaml";
  const Rig truth = sampleRig(without(true, true, false));  // pinhole-radtan: no skew, no k3
  exportKalibr(truth, path);
  ImportOptions opt;
  opt.names = truth.names();  // Kalibr names its cameras cam0, cam1, ...
  const RigImport back = importKalibr(path, opt);
  expectRoundTrip("Kalibr camchain", truth, back.rig);
  EXPECT_TRUE(anyContains(back.report.assumptions, "T_world_cam")) << back.report.fullReport();
  // Without previz's T_world_cam, cam0 is the world: the chain's relative poses are the same.
  std::string text = readTextFile(path);
  const size_t a = text.find("  T_world_cam:"), b = text.find("  camera_model:");
  text.erase(a, b - a);
  writeFileAtomic(path, text);
  const RigImport chain = importKalibr(path, {});
  EXPECT_EQ(chain.rig.cameras[1].camera.name, "cam1");
  Rig relative = truth;
  const Pose T_cam0_world = truth.cameras[0].T_world_cam.inverse();
  for (RigCamera& rc : relative.cameras) rc.T_world_cam = T_cam0_world * rc.T_world_cam;
  expectRoundTrip("Kalibr camchain, cam0 = world", relative, chain.rig, false);
  // What Kalibr cannot hold is refused, not dropped.
  try {
    exportKalibr(sampleRig(), path);
    FAIL() << "skew exported to Kalibr";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "witness01");
    EXPECT_EQ(e.context().field, "skew");
  }
}

TEST(RigImport, ColmapExportImportRoundTripsEveryIntrinsicAndPose) {
  const fs::path dir = tmpDir("colmap_roundtrip");
  const Rig truth = sampleRig(without(true, false, false));  // COLMAP has no skew; k3 goes as FULL_OPENCV
  const std::vector<fs::path> files = exportColmap(truth, dir);
  EXPECT_EQ(files.size(), 3u);
  const std::string cameras = readTextFile(dir / "cameras.txt");
  EXPECT_TRUE(contains(cameras, "1 FULL_OPENCV ")) << cameras;
  EXPECT_TRUE(contains(cameras, "2 PINHOLE ")) << cameras;
  EXPECT_TRUE(contains(cameras, "3 OPENCV ")) << cameras;
  const RigImport back = importColmap(dir, {});
  expectRoundTrip("COLMAP text", truth, back.rig);
  EXPECT_TRUE(back.report.warnings.empty()) << back.report.fullReport();
}

// A rational Brown-Conrady lens (OpenCV's k4 k5 k6) goes to COLMAP as FULL_OPENCV, whose
// parameters are fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6, and comes back exactly; to OpenCV YAML as an
// 8-term D; Kalibr's radtan has no place for it: refused naming the camera and the term.
TEST(RigImport, RationalLensRoundTripsThroughColmapAndOpenCvAndKalibrRefusesIt) {
  const fs::path dir = tmpDir("rational_roundtrip");
  Rig truth = sampleRig(without(true, false, false));
  truth.cameras[2].camera.dist.k4 = 2.2123456789;
  truth.cameras[2].camera.dist.k5 = 1.1198765432;
  truth.cameras[2].camera.dist.k6 = 0.0987654321;
  exportColmap(truth, dir / "colmap");
  const std::string cameras = readTextFile(dir / "colmap" / "cameras.txt");
  EXPECT_TRUE(contains(cameras, "3 FULL_OPENCV ")) << cameras;
  // 12 parameters, ending k3 k4 k5 k6 = 0 2.2123456789 1.1198765432 0.0987654321 (%.17g).
  EXPECT_TRUE(contains(cameras, " 0 2.2123456788999998 1.1198765432 0.098765432099999995\n")) << cameras;
  expectRoundTrip("COLMAP FULL_OPENCV rational", truth, importColmap(dir / "colmap", {}).rig);
  expectRoundTrip("OpenCV YAML rational", truth, importOpenCv(exportOpenCv(truth, dir / "opencv"), {}).rig);
  Rig kalibr = sampleRig(without(true, true, false));
  kalibr.cameras[1].camera.dist.k5 = 0.01;
  try {
    exportKalibr(kalibr, dir / "camchain.yaml");
    FAIL() << "a rational lens exported to Kalibr's radtan";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "witness02");
    EXPECT_EQ(e.context().field, "distortion.k5");
  }
  EXPECT_FALSE(fs::exists(dir / "camchain.yaml"));
}

TEST(RigImport, KRtAndProjectionRowsRoundTripEveryIntrinsicAndPose) {
  const fs::path dir = tmpDir("rows_roundtrip");
  const Rig truth = sampleRig(without(false, false, true));  // rows carry no distortion; skew they do
  writeKRtRows(truth, dir / "rig.krt.txt");
  writeProjectionRows(truth, dir / "rig.P.txt");
  for (const bool krt : {true, false}) {
    // Rows carry one size for all: compare with the cameras at that size.
    Rig same_size = truth;
    for (RigCamera& rc : same_size.cameras) {
      rc.camera.width = 1920;
      rc.camera.height = 1080;
    }
    const RigImport back = krt ? importKRtRows(dir / "rig.krt.txt", sized(1920, 1080))
                               : importProjectionRows(dir / "rig.P.txt", sized(1920, 1080));
    expectRoundTrip(krt ? "K R t rows" : "P rows", same_size, back.rig);
  }
  EXPECT_THROW(writeProjectionRows(sampleRig(), dir / "bad.txt"), Error);  // distortion
}

// ---------------------------------------------------------------------------------------------
// OpenCV FileStorage

void writeOpenCvIntrinsics(cv::FileStorage& store, const Camera& c, bool size = true) {
  if (size) store << "image_width" << c.width << "image_height" << c.height;
  store << "camera_matrix" << cvMat(c.K());
  store << "distortion_coefficients" << (cv::Mat_<double>(5, 1) << c.dist.k1, c.dist.k2, c.dist.p1, c.dist.p2, c.dist.k3);
}

TEST(RigImport, OpenCvFileWithoutImageWidthTakesTheGivenSizeAndErrorsWithoutIt) {
  const fs::path path = tmpDir("no_size") / "cam.yml";
  {
    cv::FileStorage store(path.string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, sampleRig().cameras[0].camera, false);
  }
  const RigImport given = importOpenCv({path}, sized(1280, 720));
  EXPECT_EQ(given.rig.cameras[0].camera.width, 1280);
  EXPECT_EQ(given.rig.cameras[0].camera.height, 720);
  EXPECT_TRUE(anyContains(given.report.assumptions, "1280x720 as given")) << given.report.fullReport();
  try {
    importOpenCv({path}, {});
    FAIL() << "imported without an image size";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "image_width");
    EXPECT_EQ(e.context().file, path.string());
    EXPECT_EQ(e.context().camera, "cam");
  }
  // A file with its own size keeps it; a different given size is warned about.
  {
    cv::FileStorage store(path.string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, sampleRig().cameras[0].camera, true);
  }
  const RigImport own = importOpenCv({path}, sized(1280, 720));
  EXPECT_EQ(own.rig.cameras[0].camera.width, 1920);
  EXPECT_TRUE(anyContains(own.report.warnings, "the file's size is used")) << own.report.fullReport();
}

TEST(RigImport, NamesComeFromTheGivenListOrTheFolderWhenStemsRepeat) {
  const fs::path dir = tmpDir("names");
  std::vector<fs::path> files;
  for (int i = 1; i <= 4; ++i) {
    fs::create_directories(dir / ("cam" + std::to_string(i)));
    files.push_back(dir / ("cam" + std::to_string(i)) / "config.xml");
    cv::FileStorage store(files.back().string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, sampleRig().cameras[0].camera);
    const Pose T_cam_world = sampleRig().cameras[i % 3].T_world_cam.inverse();
    Eigen::Vector3d rvec, tvec;
    poseToRvecTvec(T_cam_world, rvec, tvec);
    store << "rvec" << cvMat(rvec) << "tvec" << cvMat(tvec);
  }
  const RigImport by_folder = importOpenCv(files, {});
  EXPECT_EQ(by_folder.rig.names(), (std::vector<std::string>{"cam1", "cam2", "cam3", "cam4"}));
  ImportOptions opt;
  opt.names = {"left", "right", "top", "floor"};
  EXPECT_EQ(importOpenCv(files, opt).rig.names(), opt.names);
  opt.names = {"left", "right"};
  try {
    importOpenCv(files, opt);
    FAIL() << "2 names for 4 cameras";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "names");
  }
  // The stem where it is unique.
  EXPECT_EQ(importOpenCv({files[0]}, {}).rig.names(), (std::vector<std::string>{"config"}));
}

// The pose convention: a point projected by cv::projectPoints with the file's rvec/tvec (in
// millimetres) lands on the same pixel as previz's camera at the imported pose (metres).
TEST(RigImport, RvecTvecPlaceTheCameraWhereProjectPointsSays) {
  const fs::path path = tmpDir("rvec") / "witness.json";
  Camera cam = sampleRig().cameras[0].camera;
  cam.skew = 0;  // cv::projectPoints ignores K's skew term
  const Eigen::Vector3d rvec(0.31, -2.05, 0.42), tvec_mm(120.5, -340.25, 2875.0);
  {
    cv::FileStorage store(path.string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, cam);
    store << "rvec" << cvMat(rvec) << "tvec" << cvMat(tvec_mm);
  }
  ImportOptions opt;
  opt.units = "mm";
  const RigImport imported = importOpenCv({path}, opt);
  const RigCamera& rc = imported.rig.cameras[0];
  const std::vector<cv::Point3d> points_mm = {{100, 200, 300}, {-250, 40, -120}, {0, 0, 0}, {400, -300, 50}};
  std::vector<cv::Point2d> cv_px;
  cv::projectPoints(points_mm, cvMat(rvec), cvMat(tvec_mm), cvMat(cam.K()),
                    cv::Mat(std::vector<double>{cam.dist.k1, cam.dist.k2, cam.dist.p1, cam.dist.p2, cam.dist.k3}),
                    cv_px);
  double worst = 0;
  for (size_t i = 0; i < points_mm.size(); ++i) {
    const Eigen::Vector3d X_m = Eigen::Vector3d(points_mm[i].x, points_mm[i].y, points_mm[i].z) * 1e-3;
    const auto px = rc.camera.project(rc.T_world_cam.inverse() * X_m);
    ASSERT_TRUE(px.has_value());
    worst = std::max(worst, (*px - Eigen::Vector2d(cv_px[i].x, cv_px[i].y)).norm());
  }
  std::cout << "rvec/tvec (mm) import vs cv::projectPoints: max " << worst << " px\n";
  EXPECT_LE(worst, 1e-9);
  EXPECT_TRUE(anyContains(imported.report.assumptions, "scaled by 0.001")) << imported.report.fullReport();
}

// previz's own per-camera rig YAML (rig calibrate --yaml, multicam/rig_io.h) holds the world ->
// camera pose as R, t (with rvec beside it; here also tvec): it imports when they agree, and two
// different poses are refused naming R.
TEST(RigImport, PrevizRigYamlWithRtAndRvecImportsWhenTheyAgree) {
  const RigCamera truth = sampleRig().cameras[1];
  const Pose T_cam_world = truth.T_world_cam.inverse();
  const Eigen::Matrix3d R = T_cam_world.linear();
  const Eigen::Vector3d t = T_cam_world.translation();
  const Eigen::AngleAxisd aa(R);
  const Eigen::Vector3d rvec = aa.angle() * aa.axis();
  const auto write = [&](const fs::path& path, const Eigen::Matrix3d& R_written) {
    cv::FileStorage store(path.string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, truth.camera);
    cv::Mat Rm(3, 3, CV_64F);
    for (int i = 0; i < 9; ++i) Rm.at<double>(i / 3, i % 3) = R_written(i / 3, i % 3);
    store << "R" << Rm << "t" << cvMat(t) << "rvec" << cvMat(rvec) << "tvec" << cvMat(t);
  };
  const fs::path dir = tmpDir("previz_yaml");
  write(dir / "witness02.yaml", R);
  const RigImport imported = importOpenCv({dir / "witness02.yaml"}, ImportOptions{});
  EXPECT_LE((imported.rig.cameras[0].T_world_cam.matrix() - truth.T_world_cam.matrix()).cwiseAbs().maxCoeff(), 1e-12);
  write(dir / "other.yaml", Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()).toRotationMatrix() * R);
  try {
    importOpenCv({dir / "other.yaml"}, ImportOptions{});
    FAIL() << "two poses accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "R");
  }
}

// cv::stereoCalibrate's R, T map camera-1 points into camera 2 (x2 = R x1 + T): camera 1 is the
// world and camera 2 sits at -R^T T, in the stereo_calib sample's one-file and two-file layouts
// and in a single camera's file.
TEST(RigImport, StereoRTPutsCameraTwoAtMinusRtTInCameraOnesFrame) {
  const fs::path dir = tmpDir("stereo");
  const Rig rig = sampleRig();
  Camera left = rig.cameras[0].camera, right = rig.cameras[2].camera;
  left.width = right.width = 640;  // the stereo sample's files carry no size: it is given
  left.height = right.height = 480;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.08, Eigen::Vector3d(0.1, 1.0, 0.05).normalized()).toRotationMatrix();
  const Eigen::Vector3d T(-0.1203, 0.0021, 0.0047);
  auto writePair = [&](cv::FileStorage& store) {
    store << "M1" << cvMat(left.K()) << "D1" << (cv::Mat_<double>(1, 5) << left.dist.k1, left.dist.k2, left.dist.p1, left.dist.p2, left.dist.k3);
    store << "M2" << cvMat(right.K()) << "D2" << (cv::Mat_<double>(1, 5) << right.dist.k1, right.dist.k2, right.dist.p1, right.dist.p2, right.dist.k3);
  };
  {
    cv::FileStorage store((dir / "stereo.yml").string(), cv::FileStorage::WRITE);
    writePair(store);
    store << "R" << cvMat(R) << "T" << cvMat(T);
  }
  {
    cv::FileStorage in((dir / "intrinsics.yml").string(), cv::FileStorage::WRITE);
    writePair(in);
    cv::FileStorage ex((dir / "extrinsics.yml").string(), cv::FileStorage::WRITE);
    ex << "R" << cvMat(R) << "T" << cvMat(T) << "R1" << cvMat(Eigen::Matrix3d::Identity());
  }
  const Eigen::Vector3d expected = -R.transpose() * T;
  for (const std::vector<fs::path>& files :
       {std::vector<fs::path>{dir / "stereo.yml"}, std::vector<fs::path>{dir / "intrinsics.yml", dir / "extrinsics.yml"}}) {
    const RigImport imported = importOpenCv(files, sized(640, 480));
    ASSERT_EQ(imported.rig.cameras.size(), 2u);
    const RigCamera& c1 = imported.rig.cameras[0];
    const RigCamera& c2 = imported.rig.cameras[1];
    EXPECT_EQ(c1.camera.name, files[0].stem().string() + "_1");
    EXPECT_EQ(c2.camera.width, 640);
    EXPECT_LE((c1.T_world_cam.matrix() - Eigen::Matrix4d::Identity()).cwiseAbs().maxCoeff(), 0.0);
    EXPECT_LE((c2.T_world_cam.translation() - expected).norm(), 1e-15);
    EXPECT_LE((c2.T_world_cam.linear() - R.transpose()).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_LE(compareRigs(Rig{{RigCamera{left}, RigCamera{right}}}, imported.rig, false).intrinsics, 0.0);
    // A point of camera 1's frame, seen by camera 2: x2 = R x1 + T.
    const Eigen::Vector3d x1(0.3, -0.2, 2.5);
    EXPECT_LE((c2.T_world_cam.inverse() * x1 - (R * x1 + T)).norm(), 1e-15);
  }
  // One camera's file with R/T: that camera is the second of its pair.
  {
    cv::FileStorage store((dir / "right.yml").string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, right);
    store << "R" << cvMat(R) << "T" << cvMat(T);
  }
  const RigImport single = importOpenCv({dir / "right.yml"}, {});
  EXPECT_LE((single.rig.cameras[0].T_world_cam.translation() - expected).norm(), 1e-15);
  EXPECT_TRUE(anyContains(single.report.assumptions, "stereoCalibrate")) << single.report.fullReport();
  // An extrinsics file alone is refused: it has no cameras.
  EXPECT_THROW(importOpenCv({dir / "extrinsics.yml"}, sized(640, 480)), Error);
}

TEST(RigImport, ExtrinsicParametersAreRefusedAsPerViewBoardPoses) {
  const fs::path path = tmpDir("views") / "out_camera_data.yml";
  {
    cv::FileStorage store(path.string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, sampleRig().cameras[0].camera);
    cv::Mat views(3, 6, CV_64F, cv::Scalar(0.1));  // one rvec|tvec row per calibration view
    store << "extrinsic_parameters" << views;
  }
  try {
    importOpenCv({path}, {});
    FAIL() << "per-view board poses taken for a camera pose";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "extrinsic_parameters");
    EXPECT_TRUE(contains(e.message(), "per-view board poses")) << e.what();
  }
  // The intrinsics alone still read as before.
  EXPECT_EQ(readOpenCvCamera(path).fx, sampleRig().cameras[0].camera.fx);
}

// ROS camera_info YAML uses OpenCV's key names without OpenCV's header or matrix tags.
TEST(RigImport, RosCameraInfoYamlReads) {
  const fs::path path = tmpDir("ros") / "narrow_stereo.yaml";
  writeFileAtomic(path,
                  "image_width: 640\n"
                  "image_height: 480\n"
                  "camera_name: narrow_stereo\n"
                  "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [430.2, 0, 306.7, 0, 430.9, 247.3, 0, 0, 1]\n"
                  "distortion_model: plumb_bob\n"
                  "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [-0.33, 0.11, 0.001, -0.0004, 0]\n");
  const Camera c = importOpenCv({path}, {}).rig.cameras[0].camera;
  EXPECT_EQ(c.name, "narrow_stereo");
  EXPECT_EQ(c.fx, 430.2);
  EXPECT_EQ(c.cy, 247.3);
  EXPECT_EQ(c.dist.p2, -0.0004);
}

// ---------------------------------------------------------------------------------------------
// Kalibr

// As Kalibr writes it (PyYAML): no %YAML header, block lists at their key's indentation, long
// lists wrapped at 80 columns, imu-camera fields beside the chain.
constexpr const char* kKalibrCamchain = R"(# camchain-imucam.yaml from kalibr_calibrate_imu_camera
cam0:
  T_cam_imu:
  - [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975]
  - [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768]
  - [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28340811217029355, 0.07395907389290132, 0.00019359502856909603,
    1.7618711454538528e-05]
  distortion_model: radtan
  intrinsics: [458.6548807207614, 457.2966964634893, 367.2158039615726, 248.37534060980727]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
  timeshift_cam_imu: 0.0
cam1:
  T_cn_cnm1:
  - [0.9999973650605805, -0.0022736339764346937, -0.00031695494508158427,
    -0.11007380812718]
  - [0.0022689259426089954, 0.9998974869645488, -0.01413745157540195, 0.00039912154701]
  - [0.00034906584331009674, 0.01413669517677597, 0.9999000110023581, -0.00085370250336]
  - [0.0, 0.0, 0.0, 1.0]
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.555907e-05]
  distortion_model: radtan
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /cam1/image_raw  # right camera
  timeshift_cam_imu: -1.6e-05
)";

TEST(RigImport, KalibrCamchainAsKalibrWritesItImportsTheChain) {
  const fs::path path = tmpDir("kalibr_real") / "camchain-imucam.yaml";
  writeFileAtomic(path, kKalibrCamchain);
  const RigImport imported = importKalibr(path, {});
  ASSERT_EQ(imported.rig.cameras.size(), 2u);
  const RigCamera& c0 = imported.rig.cameras[0];
  const RigCamera& c1 = imported.rig.cameras[1];
  EXPECT_EQ(c0.camera.name, "cam0");
  EXPECT_EQ(c0.camera.fx, 458.6548807207614);
  EXPECT_EQ(c0.camera.cy, 248.37534060980727);
  EXPECT_EQ(c0.camera.dist.p2, 1.7618711454538528e-05);  // from the wrapped line
  EXPECT_EQ(c0.camera.width, 752);
  EXPECT_EQ(c1.camera.dist.p2, -3.555907e-05);
  EXPECT_TRUE(c0.T_world_cam.matrix().isIdentity(0.0));
  // T_cn_cnm1 maps cam0 points into cam1: cam1's centre in cam0's frame is -R^T t.
  Eigen::Matrix3d R;
  R << 0.9999973650605805, -0.0022736339764346937, -0.00031695494508158427, 0.0022689259426089954,
      0.9998974869645488, -0.01413745157540195, 0.00034906584331009674, 0.01413669517677597, 0.9999000110023581;
  const Eigen::Vector3d t(-0.11007380812718, 0.00039912154701, -0.00085370250336);
  EXPECT_LE((c1.T_world_cam.translation() - (-R.transpose() * t)).norm(), 1e-15);
  EXPECT_LE((c1.T_world_cam.linear() - R.transpose()).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_TRUE(imported.report.warnings.empty()) << imported.report.fullReport();
  EXPECT_TRUE(anyContains(imported.report.assumptions, "cam0")) << imported.report.fullReport();
}

// PyYAML writes keys sorted as text: cam0, cam1, cam10, cam11, cam2, ... The chain goes by number.
TEST(RigImport, KalibrCamerasChainByNumberNotByKeyOrder) {
  const fs::path path = tmpDir("kalibr_order") / "camchain.yaml";
  Rig truth;
  for (int i = 0; i < 12; ++i) {
    RigCamera rc = sampleRig(without(true, true, false)).cameras[i % 3];
    rc.camera.name = "cam" + std::to_string(i);
    rc.T_world_cam.translation() += Eigen::Vector3d(0.1 * i, 0, 0);
    truth.cameras.push_back(rc);
  }
  exportKalibr(truth, path);
  const std::string text = readTextFile(path);
  std::map<std::string, std::string> blocks;  // sorted as text
  for (size_t at = text.find("cam0:"); at != std::string::npos;) {
    const size_t next = text.find("\ncam", at + 1);
    const std::string block = text.substr(at, next == std::string::npos ? std::string::npos : next + 1 - at);
    blocks[block.substr(0, block.find(':'))] = block;
    at = next == std::string::npos ? next : next + 1;
  }
  std::string sorted;
  for (const auto& [key, block] : blocks) sorted += block;
  ASSERT_EQ(sorted.rfind("cam0:", 0), 0u);
  ASSERT_NE(sorted.find("cam1:"), std::string::npos);
  EXPECT_LT(sorted.find("cam10:"), sorted.find("cam2:"));
  writeFileAtomic(path, sorted);
  expectRoundTrip("Kalibr camchain, keys sorted as text", truth, importKalibr(path, {}).rig);
}

TEST(RigImport, KalibrEquidistantIsKannalaBrandtAndMalformedFilesAreRefusedNamingCameraAndLine) {
  const fs::path dir = tmpDir("kalibr_bad");
  // Kalibr's pinhole-equi is OpenCV fisheye's Kannala-Brandt, its four coefficients k1..k4.
  std::string fisheye = kKalibrCamchain;
  fisheye.replace(fisheye.rfind("distortion_model: radtan"), 24, "distortion_model: equidistant");
  writeFileAtomic(dir / "fisheye.yaml", fisheye);
  const Rig rig = importKalibr(dir / "fisheye.yaml", {}).rig;
  ASSERT_EQ(rig.cameras.size(), 2u);
  EXPECT_EQ(rig.cameras[0].camera.dist.model, LensModel::kBrownConrady);
  const Distortion& d = rig.cameras[1].camera.dist;
  EXPECT_EQ(d.model, LensModel::kKannalaBrandt);
  EXPECT_EQ(d.p1, 0.0);
  EXPECT_EQ(d.p2, 0.0);
  EXPECT_NE(d.k1, 0.0);
  // Written back as equidistant and read again: the same lens to the last bit.
  exportKalibr(rig, dir / "fisheye_out.yaml");
  EXPECT_TRUE(contains(readTextFile(dir / "fisheye_out.yaml"), "distortion_model: equidistant"));
  expectRoundTrip("Kalibr camchain with an equidistant camera", rig, importKalibr(dir / "fisheye_out.yaml", {}).rig);
  std::string unclosed = kKalibrCamchain;
  unclosed.erase(unclosed.find("1.7618711454538528e-05]") + 22, 1);
  writeFileAtomic(dir / "unclosed.yaml", unclosed);
  EXPECT_THROW(importKalibr(dir / "unclosed.yaml", {}), Error);
  std::string no_chain = kKalibrCamchain;
  no_chain.replace(no_chain.find("T_cn_cnm1"), 9, "T_cn_cnm2");
  writeFileAtomic(dir / "no_chain.yaml", no_chain);
  try {
    importKalibr(dir / "no_chain.yaml", {});
    FAIL() << "cam1 without T_cn_cnm1";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "cam1.T_cn_cnm1");
  }
}

// ---------------------------------------------------------------------------------------------
// COLMAP

TEST(RigImport, ColmapModelsPosesAndPixelCentresConvert) {
  const fs::path dir = tmpDir("colmap_models");
  writeFileAtomic(dir / "cameras.txt",
                  "# Camera list with one line of data per camera:\n"
                  "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                  "# Number of cameras: 5\n"
                  "1 SIMPLE_PINHOLE 640 480 500 320.5 240.5\n"
                  "2 PINHOLE 640 480 500 510 320 240\n"
                  "3 SIMPLE_RADIAL 1920 1080 1500 960 540 -0.05\n"
                  "4 RADIAL 1920 1080 1500 960 540 -0.05 0.01\n"
                  "5 OPENCV 1280 720 900 905 640 360 -0.2 0.05 0.001 -0.002\n");
  // Quaternion of a 30 deg turn about y (w first), and images whose 2-D point lines are empty or full.
  const Eigen::Quaterniond q(Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitY()));
  std::ostringstream images;
  images.precision(17);
  images << "# Image list with two lines of data per image:\n"
            "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
            "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  for (int i = 1; i <= 5; ++i) {
    const char* names[] = {"left/0001.jpg", "left/frame2.jpg", "right/0001.jpg", "right/frame4.jpg", "right/0005.jpg"};
    images << i << " " << q.w() << " " << q.x() << " " << q.y() << " " << q.z() << " 0.5 -0.25 " << 2 + i << " " << i
           << " " << names[i - 1] << "\n";
    images << (i % 2 ? "" : "2362.39 248.498 58396 1784.7 268.254 -1") << "\n";
  }
  writeFileAtomic(dir / "images.txt", images.str());
  const RigImport imported = importColmap(dir, {});
  const Rig& rig = imported.rig;
  ASSERT_EQ(rig.cameras.size(), 5u);
  // Stems where unique, the whole NAME where stems repeat (0001.jpg in left/ and right/).
  EXPECT_EQ(rig.names(), (std::vector<std::string>{"left_0001", "frame2", "right_0001", "frame4", "0005"}));
  EXPECT_EQ(rig.cameras[0].camera.cx, 320.0);  // COLMAP's 320.5 is previz's 320
  EXPECT_EQ(rig.cameras[0].camera.fy, 500.0);
  EXPECT_EQ(rig.cameras[1].camera.cx, 319.5);
  EXPECT_EQ(rig.cameras[2].camera.cx, 959.5);
  EXPECT_EQ(rig.cameras[2].camera.dist.k1, -0.05);
  EXPECT_EQ(rig.cameras[3].camera.dist.k2, 0.01);
  EXPECT_EQ(rig.cameras[4].camera.dist.p2, -0.002);
  // World -> camera: a world point projects where COLMAP's own formula puts it, minus 0.5 px.
  const Eigen::Vector3d X(0.3, 0.2, 4.0);
  const Eigen::Vector3d x = q * X + Eigen::Vector3d(0.5, -0.25, 4);
  const Eigen::Vector2d colmap_px(500 * x.x() / x.z() + 320, 510 * x.y() / x.z() + 240);  // camera 2 (PINHOLE)
  const auto px = rig.cameras[1].camera.project(rig.cameras[1].T_world_cam.inverse() * X);
  ASSERT_TRUE(px.has_value());
  EXPECT_LE((*px - (colmap_px - Eigen::Vector2d(0.5, 0.5))).norm(), 1e-12);
}

TEST(RigImport, ColmapFisheyeIsKannalaBrandtOtherModelsAndMissingFilesAreErrors) {
  const fs::path dir = tmpDir("colmap_bad");
  EXPECT_THROW(importColmap(dir, {}), Error);
  writeFileAtomic(dir / "cameras.txt", "1 OPENCV_FISHEYE 640 480 500 500 320 240 0.1 -0.02 0.003 -0.0004\n");
  writeFileAtomic(dir / "images.txt", "1 1 0 0 0 0 0 0 1 a.jpg\n\n");
  const Rig rig = importColmap(dir, {}).rig;
  ASSERT_EQ(rig.cameras.size(), 1u);
  const Camera& c = rig.cameras[0].camera;
  EXPECT_EQ(c.dist.model, LensModel::kKannalaBrandt);
  EXPECT_EQ(c.dist.k1, 0.1);
  EXPECT_EQ(c.dist.k2, -0.02);
  EXPECT_EQ(c.dist.k3, 0.003);
  EXPECT_EQ(c.dist.k4, -0.0004);
  EXPECT_EQ(c.cx, 319.5);  // COLMAP's pixel centres are at +0.5
  // Written back as OPENCV_FISHEYE and read again: the same lens.
  const fs::path out = dir / "out";
  exportColmap(rig, out);
  expectRoundTrip("COLMAP OPENCV_FISHEYE", rig, importColmap(out, {}).rig);
  writeFileAtomic(dir / "cameras.txt", "1 FOV 640 480 500 500 320 240 0.9\n");
  try {
    importColmap(dir, {});
    FAIL() << "FOV imported";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.message(), "FOV")) << e.what();
    EXPECT_EQ(e.context().field, "MODEL");
  }
}

// ---------------------------------------------------------------------------------------------
// The rotation rule, units and axes, whole-rig warnings

std::string krtRow(const std::string& name, const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  std::ostringstream s;
  s.precision(17);
  s << name << " 1500 0 320 0 1500 240 0 0 1";
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) s << " " << R(r, c);
  s << " " << t.x() << " " << t.y() << " " << t.z() << "\n";
  return s.str();
}

// Middlebury's dinoSparseRing rows are orthonormal only to 1.4e-6: fixed with a warning that
// names the camera; a matrix orthonormal to 1e-3 (or a reflection) is refused naming it.
TEST(RigImport, NearOrthonormalRotationIsFixedWithAWarningAndABadOneRefused) {
  const fs::path dir = tmpDir("rotation_rule");
  const Eigen::Matrix3d R = lookAt({1, 2, 0.5}, {0, 0, 0}).linear().transpose();
  const Eigen::Matrix3d near = (1 + 0.7e-6) * R;  // R^T R = (1 + 1.4e-6) I
  writeFileAtomic(dir / "near.txt", krtRow("good", R, {0, 0, 2}) + krtRow("dino07", near, {0, 0, 2.5}));
  const RigImport fixed = importKRtRows(dir / "near.txt", sized(640, 480));
  ASSERT_EQ(fixed.report.warnings.size(), 1u) << fixed.report.fullReport();
  EXPECT_TRUE(contains(fixed.report.warnings[0], "dino07")) << fixed.report.warnings[0];
  EXPECT_TRUE(contains(fixed.report.warnings[0], "1.4e-06")) << fixed.report.warnings[0];
  const Eigen::Matrix3d Rf = fixed.rig.cameras[1].T_world_cam.linear();
  EXPECT_LE((Rf.transpose() * Rf - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LE((Rf.transpose() - R).cwiseAbs().maxCoeff(), 1e-15);
  for (const auto& [name, bad] : {std::pair<std::string, Eigen::Matrix3d>{"skewed", R + 1e-3 * Eigen::Matrix3d::Ones()},
                                  std::pair<std::string, Eigen::Matrix3d>{"mirrored", -R}}) {
    writeFileAtomic(dir / "bad.txt", krtRow("good", R, {0, 0, 2}) + krtRow(name, bad, {0, 0, 2}));
    try {
      importKRtRows(dir / "bad.txt", sized(640, 480));
      FAIL() << name << " imported";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().camera, name);
      EXPECT_EQ(e.context().field, "R");
      EXPECT_EQ(e.context().file, (dir / "bad.txt").string());
    }
  }
  // The same rule in an OpenCV file's R.
  const fs::path cv_path = dir / "cam.yml";
  {
    cv::FileStorage store(cv_path.string(), cv::FileStorage::WRITE);
    writeOpenCvIntrinsics(store, sampleRig().cameras[0].camera);
    store << "R" << cvMat(near) << "T" << cvMat(Eigen::Vector3d(0.1, 0, 0));
  }
  EXPECT_TRUE(anyContains(importOpenCv({cv_path}, {}).report.warnings, "replaced by the nearest rotation"));
}

// The real data: Oxford's dino (36 P rows) and Middlebury's temple (16 K R t rows).
TEST(RigImport, TheDinoAndTempleRowsImport) {
  const fs::path data(PREVIZ_SHARED_DATA);
  const fs::path dino = data / "oxford-dino" / "dino.P.txt", temple = data / "middlebury-temple" / "templeSR_par.txt";
  ASSERT_TRUE(fs::exists(dino) && fs::exists(temple)) << "real data missing under " << data.string();
  const RigImport d = importProjectionRows(dino, sized(720, 576));
  ASSERT_EQ(d.rig.cameras.size(), 36u);
  EXPECT_EQ(d.rig.cameras[35].camera.name, "viff035");
  const RigImport t = importKRtRows(temple, sized(640, 480));
  ASSERT_EQ(t.rig.cameras.size(), 16u);
  std::cout << "dino: " << d.report.warnings.size() << " warnings; temple: " << t.report.warnings.size()
            << " warnings\n"
            << d.report.fullReport() << t.report.fullReport();
  // Turntable and ring: every camera looks at the object, so no look-away warning. The dino's
  // rows are left-handed as written (det M < 0 with the object in front): mirrored, said so.
  EXPECT_FALSE(anyContains(d.report.warnings, "look away"));
  EXPECT_TRUE(anyContains(d.report.warnings, "x -> -x"));
  // The object, on the turntable axis near z = -0.66 (data README), is in front of every camera
  // and inside its image; the images' up is the world's +z.
  for (const RigCamera& rc : d.rig.cameras) {
    const Eigen::Vector3d X_cam = rc.T_world_cam.inverse() * Eigen::Vector3d(0, 0, -0.66);
    ASSERT_GT(X_cam.z(), 0) << rc.camera.name;
    EXPECT_TRUE(rc.camera.inImage(*rc.camera.project(X_cam))) << rc.camera.name;
    EXPECT_GT((rc.T_world_cam.linear() * Eigen::Vector3d(0, -1, 0)).z(), 0.99) << rc.camera.name;
  }
  EXPECT_FALSE(anyContains(t.report.warnings, "look away"));
  // The legacy readers apply the same rule.
  EXPECT_EQ(readKRtRows(temple, 640, 480).cameras.size(), 16u);
  EXPECT_EQ(readProjectionRows(dino, 720, 576).cameras.size(), 36u);
}

// P's sign is free (a DLT gives either): rows all negated import as the same cameras. Rows of a
// left-handed world (the same cameras with x mirrored) keep their pixels and are mirrored back.
TEST(RigImport, NegatedProjectionRowsAreTheSameCamerasAndLeftHandedOnesAreMirrored) {
  const fs::path dir = tmpDir("p_sign");
  const Rig truth = sampleRig(without(false, false, true));
  auto writeRowsOf = [&](const fs::path& path, double sign, bool mirror_x) {
    std::ostringstream s;
    s.precision(17);
    for (const RigCamera& rc : truth.cameras) {
      Eigen::Matrix<double, 3, 4> P = sign * projectionMatrix(rc);
      if (mirror_x) P.col(0) *= -1.0;  // the world seen through x -> -x
      s << rc.camera.name;
      for (int i = 0; i < 12; ++i) s << " " << P(i / 4, i % 4);
      s << "\n";
    }
    writeFileAtomic(path, s.str());
  };
  writeRowsOf(dir / "negated.txt", -1.0, false);
  writeRowsOf(dir / "left.txt", 1.0, true);
  Rig same_size = truth;
  for (RigCamera& rc : same_size.cameras) {
    rc.camera.width = 1920;
    rc.camera.height = 1080;
  }
  const RigImport negated = importProjectionRows(dir / "negated.txt", sized(1920, 1080));
  expectRoundTrip("P rows, negated", same_size, negated.rig);
  EXPECT_TRUE(negated.report.warnings.empty()) << negated.report.fullReport();
  const RigImport left = importProjectionRows(dir / "left.txt", sized(1920, 1080));
  expectRoundTrip("P rows, left-handed world mirrored back", same_size, left.rig);
  EXPECT_TRUE(anyContains(left.report.warnings, "left-handed")) << left.report.fullReport();
}

TEST(RigImport, UnitsScaleTranslationsAndFlipTurnsTheWorldZUp) {
  const fs::path dir = tmpDir("units_flip");
  // A y-up world (Maya): a camera 1500 mm up the y axis, 4 m back along +z, looking at the origin.
  const Pose T_yup_cam = lookAt({0, 1500, 4000}, {0, 0, 0}, Eigen::Vector3d::UnitY());
  const Pose T_cam_yup = T_yup_cam.inverse();
  const Pose T_yup_cam2 = lookAt({3000, 1500, -500}, {0, 0, 0}, Eigen::Vector3d::UnitY());
  writeFileAtomic(dir / "rows.txt", krtRow("a", T_cam_yup.linear(), T_cam_yup.translation()) +
                                        krtRow("b", T_yup_cam2.inverse().linear(), T_yup_cam2.inverse().translation()));
  ImportOptions opt = sized(640, 480);
  opt.units = "mm";
  opt.flip = "y-up";
  const RigImport imported = importKRtRows(dir / "rows.txt", opt);
  const Pose& T = imported.rig.cameras[0].T_world_cam;
  // (x, y, z) -> (x, -z, y), mm -> m: up is z, the camera 1.5 m high, 4 m along -y.
  EXPECT_LE((T.translation() - Eigen::Vector3d(0, -4.0, 1.5)).norm(), 1e-12);
  // Its image's up (-y of the camera) is the world's +z side: the horizon stays level.
  EXPECT_NEAR((T.linear() * Eigen::Vector3d(1, 0, 0)).z(), 0.0, 1e-12);
  EXPECT_GT((T.linear() * Eigen::Vector3d(0, -1, 0)).z(), 0.9);
  EXPECT_TRUE(anyContains(imported.report.assumptions, "(x, y, z) -> (x, -z, y)")) << imported.report.fullReport();
  EXPECT_TRUE(contains(imported.rig.world_frame, "y-up"));
  opt.units = "km";
  EXPECT_THROW(importKRtRows(dir / "rows.txt", opt), Error);
}

TEST(RigImport, EveryCameraAtTheOriginIsWarnedAbout) {
  const fs::path dir = tmpDir("origin");
  std::vector<fs::path> files;
  for (const char* name : {"a.yml", "b.yml"}) {
    files.push_back(dir / name);
    writeOpenCvCamera(sampleRig().cameras[0].camera, files.back());  // intrinsics only
  }
  const RigImport imported = importOpenCv(files, {});
  EXPECT_TRUE(anyContains(imported.report.warnings, "every camera sits at the world origin"))
      << imported.report.fullReport();
  EXPECT_TRUE(anyContains(imported.report.assumptions, "no pose in the file")) << imported.report.fullReport();
  EXPECT_TRUE(rigPoseWarnings(sampleRig()).empty());
}

TEST(RigImport, CamerasLookingAwayFromTheirCommonPointAreWarnedAbout) {
  Rig inward, outward;
  for (int i = 0; i < 6; ++i) {
    const Eigen::Vector3d eye(3 * std::cos(i), 3 * std::sin(i), 1.5);
    RigCamera rc;
    rc.camera = sampleRig().cameras[0].camera;
    rc.camera.name = "w" + std::to_string(i);
    rc.T_world_cam = lookAt(eye, {0, 0, 1});
    inward.cameras.push_back(rc);
    rc.T_world_cam = lookAt(eye, 2 * eye - Eigen::Vector3d(0, 0, 1));
    outward.cameras.push_back(rc);
  }
  EXPECT_TRUE(rigPoseWarnings(inward).empty());
  const std::vector<std::string> w = rigPoseWarnings(outward);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_TRUE(contains(w[0], "behind 6 of 6 cameras")) << w[0];
  // A parallel stereo pair has no common point: nothing to say.
  Rig pair;
  pair.cameras = {inward.cameras[0], inward.cameras[1]};
  pair.cameras[1].T_world_cam = pair.cameras[0].T_world_cam * Pose(Eigen::Translation3d(0.12, 0, 0));
  EXPECT_TRUE(rigPoseWarnings(pair).empty());
}

}  // namespace
}  // namespace previz
