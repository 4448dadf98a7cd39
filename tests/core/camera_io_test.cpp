// Camera interchange: OpenCV YAML/XML, projection-matrix decomposition, KRt / P text rows
// (including the real Middlebury templeSR_par.txt).
#include "core/camera_io.h"

#include <cmath>
#include <filesystem>
#include <random>
#include <tuple>
#include <vector>

#include <Eigen/SVD>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/io.h"
#include "scratch.h"

namespace fs = std::filesystem;

namespace previz {
namespace {

fs::path tmpDir(const std::string& name) {
  return test::scratchDir("camera_io_test", name);
}

Camera sampleCamera() {
  Camera c;
  c.name = "cam";
  c.width = 1920;
  c.height = 1080;
  c.fx = 1412.3456789012345;
  c.fy = 1409.8765432109876;
  c.cx = 961.123456789;
  c.cy = 538.987654321;
  c.skew = 0.25;
  c.dist = {-0.2345678901234, 0.0876543210987, 0.000123456789, -0.000987654321, -0.0123456789};
  return c;
}

void expectSameCamera(const Camera& a, const Camera& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.fx, b.fx);
  EXPECT_EQ(a.fy, b.fy);
  EXPECT_EQ(a.cx, b.cx);
  EXPECT_EQ(a.cy, b.cy);
  EXPECT_EQ(a.skew, b.skew);
  EXPECT_EQ(a.dist.k1, b.dist.k1);
  EXPECT_EQ(a.dist.k2, b.dist.k2);
  EXPECT_EQ(a.dist.p1, b.dist.p1);
  EXPECT_EQ(a.dist.p2, b.dist.p2);
  EXPECT_EQ(a.dist.k3, b.dist.k3);
  EXPECT_EQ(a.dist.k4, b.dist.k4);
  EXPECT_EQ(a.dist.k5, b.dist.k5);
  EXPECT_EQ(a.dist.k6, b.dist.k6);
  EXPECT_EQ(a.dist.model, b.dist.model);
}

TEST(CameraIo, OpenCvYamlAndXmlRoundTripsAreExact) {
  const fs::path dir = tmpDir("roundtrip");
  for (const char* name : {"cam.yml", "cam.yaml", "cam.xml", "cam.json"}) {
    writeOpenCvCamera(sampleCamera(), dir / name);
    const Camera back = readOpenCvCamera(dir / name);
    EXPECT_EQ(back.name, "cam");
    expectSameCamera(sampleCamera(), back);
  }
  // What we write is what OpenCV itself reads.
  cv::FileStorage fs((dir / "cam.yml").string(), cv::FileStorage::READ);
  cv::Mat K, D;
  fs["camera_matrix"] >> K;
  fs["distortion_coefficients"] >> D;
  EXPECT_EQ(K.at<double>(0, 1), 0.25);
  EXPECT_EQ(D.total(), 5u);
  EXPECT_EQ(static_cast<int>(fs["image_width"]), 1920);
  EXPECT_THROW(writeOpenCvCamera(sampleCamera(), dir / "cam.txt"), Error);
}

// Exactly the calls of OpenCV's samples/cpp/calibration.cpp (saveCameraParams): 8x1 distortion
// vector, extra fields around the ones we read.
TEST(CameraIo, ReadsTheFileOpenCvsCalibrationSampleWrites) {
  const fs::path path = tmpDir("sample") / "out_camera_data.yml";
  const Camera truth = sampleCamera();
  cv::Mat cameraMatrix = cv::Mat::eye(3, 3, CV_64F);
  cameraMatrix.at<double>(0, 0) = truth.fx;
  cameraMatrix.at<double>(1, 1) = truth.fy;
  cameraMatrix.at<double>(0, 2) = truth.cx;
  cameraMatrix.at<double>(1, 2) = truth.cy;
  cv::Mat distCoeffs = cv::Mat::zeros(8, 1, CV_64F);
  distCoeffs.at<double>(0) = truth.dist.k1;
  distCoeffs.at<double>(1) = truth.dist.k2;
  distCoeffs.at<double>(2) = truth.dist.p1;
  distCoeffs.at<double>(3) = truth.dist.p2;
  distCoeffs.at<double>(4) = truth.dist.k3;
  {
    cv::FileStorage fs(path.string(), cv::FileStorage::WRITE);
    fs << "calibration_time" << "Tue 25 Nov 2025 10:00:00 UTC";
    fs << "nframes" << 14;
    fs << "image_width" << truth.width;
    fs << "image_height" << truth.height;
    fs << "board_width" << 9;
    fs << "board_height" << 6;
    fs << "square_size" << 0.025f;
    fs << "flags" << 0;
    fs << "camera_matrix" << cameraMatrix;
    fs << "distortion_coefficients" << distCoeffs;
    fs << "avg_reprojection_error" << 0.41;
    fs << "per_view_reprojection_errors" << cv::Mat(std::vector<float>{0.4f, 0.42f});
  }
  const Camera c = readOpenCvCamera(path, "left");
  EXPECT_EQ(c.name, "left");
  Camera expected = truth;
  expected.skew = 0;
  expectSameCamera(expected, c);

  // The sample with CALIB_RATIONAL_MODEL: D's k4 k5 k6 are the rational terms, read as they are.
  {
    cv::FileStorage fs(path.string(), cv::FileStorage::WRITE);
    distCoeffs.at<double>(5) = 0.01;
    distCoeffs.at<double>(6) = -0.002;
    distCoeffs.at<double>(7) = 0.0003;
    fs << "image_width" << truth.width << "image_height" << truth.height << "camera_matrix" << cameraMatrix
       << "distortion_coefficients" << distCoeffs;
  }
  const Camera rational = readOpenCvCamera(path);
  EXPECT_EQ(rational.dist.k4, 0.01);
  EXPECT_EQ(rational.dist.k5, -0.002);
  EXPECT_EQ(rational.dist.k6, 0.0003);
  EXPECT_TRUE(rational.dist.isRational());

  // 12 and 14 coefficients (thin prism, tilt): read while those terms are zero; a non-zero one is
  // refused naming the file, the count and the term.
  for (const int n : {12, 14}) {
    cv::Mat D = cv::Mat::zeros(n, 1, CV_64F);
    for (int i = 0; i < 8; ++i) D.at<double>(i) = distCoeffs.at<double>(i);
    {
      cv::FileStorage fs(path.string(), cv::FileStorage::WRITE);
      fs << "image_width" << truth.width << "image_height" << truth.height << "camera_matrix" << cameraMatrix
         << "distortion_coefficients" << D;
    }
    EXPECT_EQ(readOpenCvCamera(path).dist, rational.dist) << n << " coefficients";
    D.at<double>(n - 1) = 0.001;
    {
      cv::FileStorage fs(path.string(), cv::FileStorage::WRITE);
      fs << "image_width" << truth.width << "image_height" << truth.height << "camera_matrix" << cameraMatrix
         << "distortion_coefficients" << D;
    }
    try {
      readOpenCvCamera(path);
      FAIL() << n << " coefficients with a non-zero last term accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, "distortion_coefficients");
      EXPECT_EQ(e.context().file, path.string());
      EXPECT_NE(e.message().find("of " + std::to_string(n)), std::string::npos) << e.message();
      EXPECT_NE(e.message().find(n == 12 ? "s4" : "tauY"), std::string::npos) << e.message();
    }
  }
  // A length OpenCV does not have is refused naming the count.
  {
    cv::FileStorage fs(path.string(), cv::FileStorage::WRITE);
    fs << "image_width" << truth.width << "image_height" << truth.height << "camera_matrix" << cameraMatrix
       << "distortion_coefficients" << cv::Mat(cv::Mat::zeros(6, 1, CV_64F));
  }
  try {
    readOpenCvCamera(path);
    FAIL() << "6 coefficients accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "distortion_coefficients");
    EXPECT_NE(e.message().find("got 6"), std::string::npos) << e.message();
  }
}

// A rational lens written as OpenCV's 8-term D and read back bit for bit; OpenCV reads the same
// file and projects through it as we do.
TEST(CameraIo, RationalLensRoundTripsAsOpenCvsEightTermD) {
  const fs::path path = tmpDir("rational") / "wide.yaml";
  Camera c = sampleCamera();
  c.skew = 0;
  c.dist = {1.8412345678901, 0.6198765432109, 0.000812345, -0.001123456, 0.0212345678, 2.2123456789,
            1.1198765432, 0.0987654321};
  writeOpenCvCamera(c, path);
  expectSameCamera(c, readOpenCvCamera(path));
  cv::FileStorage fs(path.string(), cv::FileStorage::READ);
  cv::Mat K, D;
  fs["camera_matrix"] >> K;
  fs["distortion_coefficients"] >> D;
  ASSERT_EQ(D.total(), 8u);
  const std::vector<cv::Point3d> p = {{0.3, -0.2, 1.0}, {-0.6, 0.35, 1.2}};
  std::vector<cv::Point2d> theirs;
  cv::projectPoints(p, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, theirs);
  for (size_t i = 0; i < p.size(); ++i) {
    const auto ours = c.project(Eigen::Vector3d(p[i].x, p[i].y, p[i].z));
    ASSERT_TRUE(ours);
    EXPECT_NEAR(ours->x(), theirs[i].x, 1e-9);
    EXPECT_NEAR(ours->y(), theirs[i].y, 1e-9);
  }
  // A plain lens is still written with 5 coefficients.
  c.dist.k4 = c.dist.k5 = c.dist.k6 = 0;
  writeOpenCvCamera(c, path);
  cv::FileStorage plain(path.string(), cv::FileStorage::READ);
  plain["distortion_coefficients"] >> D;
  EXPECT_EQ(D.total(), 5u);
}

TEST(CameraIo, MalformedOpenCvFilesNameFileAndField) {
  const fs::path dir = tmpDir("malformed");
  {
    cv::FileStorage fs((dir / "nok.yml").string(), cv::FileStorage::WRITE);
    fs << "image_width" << 640 << "image_height" << 480;
    fs << "distortion_coefficients" << cv::Mat::zeros(5, 1, CV_64F);
  }
  try {
    readOpenCvCamera(dir / "nok.yml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "camera_matrix");
    EXPECT_EQ(e.context().file, (dir / "nok.yml").string());
  }
  writeFileAtomic(dir / "garbage.yml", "{{{ not yaml at all");
  EXPECT_THROW(readOpenCvCamera(dir / "garbage.yml"), Error);
  EXPECT_THROW(readOpenCvCamera(dir / "absent.yml"), Error);
}

// Reading `file` throws an Error that names it, with `what` in its message.
void expectRefused(const fs::path& file, const std::string& what) {
  try {
    readOpenCvCamera(file);
    FAIL() << "read " << file;
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, file.string());
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

// A camera file cut short inside an XML tag (found by fuzz/opencv_camera.cpp: OpenCV 4.6's XML
// reader dereferenced null) is refused naming the file, whatever its extension says.
TEST(CameraIo, XmlCutShortInsideATagIsRefusedNamingTheFile) {
  const fs::path dir = tmpDir("cut");
  writeOpenCvCamera(sampleCamera(), dir / "whole.xml");
  const std::string whole = readTextFile(dir / "whole.xml");
  const std::string cut = whole.substr(0, whole.rfind("type_id=") + 8);
  ASSERT_GT(cut.size(), 8u);
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"cut.xml", cut},
                                   {"cut-bom.json", "\xEF\xBB\xBF" + cut},
                                   {"cut-newline.xml", cut + "\n  \n"},
                                   {"cut-tag.xml", whole.substr(0, whole.rfind('<') + 2)}}) {
    SCOPED_TRACE(name);
    writeFileAtomic(dir / name, text);
    expectRefused(dir / name, "cut short");
  }
  // The whole file, with spaces after its last '>', still reads.
  writeFileAtomic(dir / "whole-spaces.xml", whole + "\n\n  ");
  expectSameCamera(sampleCamera(), readOpenCvCamera(dir / "whole-spaces.xml"));
}

// YAML shapes that OpenCV 4.6's reader never returns from (found by fuzz/opencv_camera.cpp) are
// refused before it sees them, naming the file and line; nothing a YAML writer puts there is.
TEST(CameraIo, YamlThatHangsOpenCvIsRefusedNamingTheLine) {
  const fs::path dir = tmpDir("yaml_hangs");
  const std::vector<std::tuple<std::string, std::string, std::string>> cases = {
      {"dedent.yaml", "%YAML:1.0\n M: 0\n0\n0\n", "line 2 starts the document at column 2"},
      {"second-document.yaml", " L: 1\n---\n -\n", "line 1 starts the document at column 2"},
      {"after-end.yaml", "a: 1\n...-]\n-\n", "line 2 has text after the document end"},
      {"start-text.yaml", "%YAML:1.0\n--- a: 1\n.0\n-\n", "line 2 has text after the document start"},
      {"start-glued.yaml", "%YAML:1.0\n---ht: 48480\n.0\n--x\n", "line 2 has text after the document start"},
      {"start-dashes.yaml", "%YAML:1.0\n---\nL: 0\n----\n\xff\n", "line 4 has text after the document start"}};
  for (const auto& [name, text, what] : cases) {
    SCOPED_TRACE(name);
    writeFileAtomic(dir / name, text);
    expectRefused(dir / name, what);
  }
  // A comment after the document start, as people write one, still reads.
  writeOpenCvCamera(sampleCamera(), dir / "whole.yml");
  std::string whole = readTextFile(dir / "whole.yml");
  const size_t start = whole.find("---\n");
  ASSERT_NE(start, std::string::npos);
  writeFileAtomic(dir / "comment.yml", whole.replace(start, 4, "--- # witness 3, re-shot\n"));
  expectSameCamera(sampleCamera(), readOpenCvCamera(dir / "comment.yml"));
}

Eigen::Matrix3d randomRotation(std::mt19937& rng) {
  std::normal_distribution<double> g(0, 1);
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  return q.normalized().toRotationMatrix();
}

TEST(CameraIo, ProjectionDecompositionRecoversKRtWithPositiveDiagonalAndProperRotation) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1, 1);
  double worst_K = 0, worst_R = 0, worst_t = 0, worst_cv = 0;
  for (int i = 0; i < 200; ++i) {
    RigCamera truth;
    truth.camera.name = "p";
    truth.camera.width = 1280;
    truth.camera.height = 720;
    truth.camera.fx = 800 + 400 * (u(rng) + 1);
    truth.camera.fy = truth.camera.fx * (1 + 0.05 * u(rng));
    truth.camera.cx = 640 + 50 * u(rng);
    truth.camera.cy = 360 + 50 * u(rng);
    truth.camera.skew = i % 2 ? 2 * u(rng) : 0.0;
    truth.T_world_cam.linear() = randomRotation(rng);
    truth.T_world_cam.translation() = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 5;
    const Eigen::Matrix<double, 3, 4> P = projectionMatrix(truth);
    // Any non-zero scale, either sign, is the same camera.
    const double scale = (i % 3 == 0 ? -1 : 1) * std::pow(10.0, 3 * u(rng));
    const RigCamera back = rigCameraFromProjection(scale * P, 1280, 720, "p");
    const Eigen::Matrix3d K = back.camera.K();
    EXPECT_GT(K(0, 0), 0);
    EXPECT_GT(K(1, 1), 0);
    const Eigen::Matrix3d R = back.T_world_cam.linear();
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    worst_K = std::max(worst_K, (K - truth.camera.K()).cwiseAbs().maxCoeff() / truth.camera.fx);
    worst_R = std::max(worst_R, (R - truth.T_world_cam.linear()).cwiseAbs().maxCoeff());
    worst_t = std::max(worst_t, (back.T_world_cam.translation() - truth.T_world_cam.translation()).norm());
    // OpenCV's decomposition agrees on K (normalized).
    cv::Mat Pcv(3, 4, CV_64F), Kcv, Rcv, Ccv;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) Pcv.at<double>(r, c) = P(r, c);
    cv::decomposeProjectionMatrix(Pcv, Kcv, Rcv, Ccv);
    Kcv /= Kcv.at<double>(2, 2);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        worst_cv = std::max(worst_cv, std::abs(Kcv.at<double>(r, c) - K(r, c)) / truth.camera.fx);
  }
  std::cout << "decomposition: max relative K error " << worst_K << ", R " << worst_R << ", centre " << worst_t
            << " m, |K - OpenCV K| / fx " << worst_cv << "\n";
  EXPECT_LE(worst_K, 1e-12);
  EXPECT_LE(worst_R, 1e-12);
  EXPECT_LE(worst_t, 1e-11);
  EXPECT_LE(worst_cv, 1e-10);
}

TEST(CameraIo, KRtAndProjectionRowsRoundTrip) {
  const fs::path dir = tmpDir("rows");
  std::mt19937 rng(4);
  Rig rig;
  for (int i = 0; i < 4; ++i) {
    RigCamera rc;
    rc.camera.name = "view" + std::to_string(i);
    rc.camera.width = 640;
    rc.camera.height = 480;
    rc.camera.fx = 1500 + i;
    rc.camera.fy = 1510;
    rc.camera.cx = 300;
    rc.camera.cy = 250;
    rc.T_world_cam = lookAt({std::cos(i), std::sin(i), 0.3}, {0, 0, 0});
    rig.cameras.push_back(rc);
  }
  writeKRtRows(rig, dir / "par.txt");
  const Rig back = readKRtRows(dir / "par.txt", 640, 480);
  ASSERT_EQ(back.cameras.size(), 4u);
  // P rows written from the same cameras decompose back to them.
  std::string prows = "# name p11..p34\n";
  for (const auto& rc : rig.cameras) {
    std::ostringstream s;
    s.precision(17);
    s << rc.camera.name;
    const auto P = projectionMatrix(rc);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) s << ' ' << P(r, c);
    prows += s.str() + "\n";
  }
  writeFileAtomic(dir / "p.txt", prows);
  const Rig from_p = readProjectionRows(dir / "p.txt", 640, 480);
  for (size_t i = 0; i < 4; ++i) {
    for (const Rig* r : {&back, &from_p}) {
      const RigCamera& b = r->cameras[i];
      EXPECT_EQ(b.camera.name, rig.cameras[i].camera.name);
      EXPECT_LE((b.camera.K() - rig.cameras[i].camera.K()).cwiseAbs().maxCoeff(), 1e-9);
      EXPECT_LE((b.T_world_cam.matrix() - rig.cameras[i].T_world_cam.matrix()).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
  Rig distorted = rig;
  distorted.cameras[0].camera.dist.k1 = 0.1;
  EXPECT_THROW(writeKRtRows(distorted, dir / "bad.txt"), Error);
}

TEST(CameraIo, MalformedRowsNameTheLine) {
  const fs::path dir = tmpDir("bad_rows");
  writeFileAtomic(dir / "short.txt", "2\na.png 1 0 0 0 1 0 0 0 1 1 0 0 0 1 0 0 0 1 0 0 1\nb.png 1 0 0\n");
  try {
    readKRtRows(dir / "short.txt", 640, 480);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "b.png");
    EXPECT_NE(std::string(e.what()).find("line 3"), std::string::npos) << e.what();
  }
  writeFileAtomic(dir / "count.txt", "3\na.png 1 0 0 0 1 0 0 0 1 1 0 0 0 1 0 0 0 1 0 0 1\n");
  EXPECT_THROW(readKRtRows(dir / "count.txt", 640, 480), Error);
  writeFileAtomic(dir / "notrot.txt", "a.png 1 0 0 0 1 0 0 0 1 2 0 0 0 1 0 0 0 1 0 0 1\n");
  try {
    readKRtRows(dir / "notrot.txt", 640, 480);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "R");
  }
  writeFileAtomic(dir / "nan.txt", "a.png 1 0 0 0 1 0 0 0 1 1 0 0 0 1 0 0 0 1 0 zero 1\n");
  EXPECT_THROW(readKRtRows(dir / "nan.txt", 640, 480), Error);
}

// The real Middlebury templeSparseRing calibration (Seitz et al.): 16 views on a ring.
TEST(CameraIo, ReadsTheRealMiddleburyTempleRing) {
  const fs::path path = fs::path(PREVIZ_SHARED_DATA) / "middlebury-temple" / "templeSR_par.txt";
  ASSERT_TRUE(fs::exists(path)) << "real data missing: " << path.string()
                                << " (see ../shared/data/README.md)";
  const Rig rig = readKRtRows(path, 640, 480);
  ASSERT_EQ(rig.cameras.size(), 16u);  // the file's first line says 16
  EXPECT_EQ(rig.cameras.front().camera.name, "templeSR0001.png");
  // Bounding box from the data set's README.txt.
  const Eigen::Vector3d bb_min(-0.073568, 0.021728, -0.012445), bb_max(0.028855, 0.181892, 0.062736);
  const Eigen::Vector3d centre = 0.5 * (bb_min + bb_max);
  Eigen::Matrix<double, 3, 16> C;
  for (int i = 0; i < 16; ++i) {
    const RigCamera& rc = rig.cameras[i];
    const Camera& cam = rc.camera;
    EXPECT_EQ(cam.fx, 1520.4);
    EXPECT_EQ(cam.fy, 1525.9);
    EXPECT_EQ(cam.cx, 302.32);
    EXPECT_EQ(cam.cy, 246.87);
    EXPECT_EQ(cam.skew, 0.0);
    const Eigen::Matrix3d R = rc.T_world_cam.linear();
    EXPECT_LE((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    const auto px = cam.project(rc.T_world_cam.inverse() * centre);
    ASSERT_TRUE(px.has_value()) << cam.name;
    EXPECT_TRUE(cam.inImage(*px)) << cam.name << " sees the object centre at " << px->transpose();
    // The whole box is in front of every camera.
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d corner((k & 1) ? bb_max.x() : bb_min.x(), (k & 2) ? bb_max.y() : bb_min.y(),
                                   (k & 4) ? bb_max.z() : bb_min.z());
      EXPECT_GT((rc.T_world_cam.inverse() * corner).z(), 0.0);
    }
    C.col(i) = rc.T_world_cam.translation();
  }
  // A ring: centres at a near-constant distance from the object, close to one plane, and
  // surrounding it (their mean sits near the object, far inside the ring).
  const Eigen::Vector3d mean = C.rowwise().mean();
  double dmin = INFINITY, dmax = 0;
  for (int i = 0; i < 16; ++i) {
    const double d = (C.col(i) - centre).norm();
    dmin = std::min(dmin, d);
    dmax = std::max(dmax, d);
  }
  const Eigen::JacobiSVD<Eigen::Matrix<double, 3, 16>> svd(C.colwise() - mean);
  const Eigen::Vector3d sv = svd.singularValues();
  std::cout << "Middlebury ring: camera distance " << dmin << " .. " << dmax << " m, plane thickness ratio "
            << sv(2) / sv(0) << ", |mean centre - object| " << (mean - centre).norm() << " m\n";
  EXPECT_LT((dmax - dmin) / dmin, 0.05);
  EXPECT_LT(sv(2) / sv(0), 0.1);
  EXPECT_LT((mean - centre).norm(), 0.3 * dmin);
}

}  // namespace
}  // namespace previz
