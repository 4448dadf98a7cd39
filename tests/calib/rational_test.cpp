// OpenCV's rational Brown–Conrady model (k4 k5 k6, CALIB_RATIONAL_MODEL) through the intrinsic
// solve (issue 34): a wide camera with rational truth over seeds, beside cv::calibrateCamera with
// CALIB_RATIONAL_MODEL on the same points, and OpenCV's real chessboard views beside it.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calib/detect.h"
#include "calib/intrinsics.h"
#include "core/io.h"
#include "tests/calib/solve_fixtures.h"
#include "tests/real_data.h"

namespace previz::calib {
namespace {

using testing::projectedViews;

// A 1280 x 960 witness with a wide lens in the rational model, of the size OpenCV's rational
// calibrations of wide lenses report (numerator and denominator terms of the same order, which
// nearly cancel: radial = 1 - 0.36 r^2 + ... near the axis); f 700 px, the image corners 57
// degrees off the axis.
Camera rationalWitness() {
  Camera c;
  c.name = "rational";
  c.width = 1280;
  c.height = 960;
  c.fx = 700.0;
  c.fy = 699.3;
  c.cx = 641.3;
  c.cy = 478.6;
  c.dist = {1.85, 0.62, 0.0008, -0.0011, 0.021, 2.21, 1.12, 0.098};
  return c;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// The points of the views that found a board, as cv::calibrateCamera takes them.
void openCvPoints(const std::vector<ViewObservations>& views, const BoardSpec& board,
                  std::vector<std::vector<cv::Point3f>>& object, std::vector<std::vector<cv::Point2f>>& image) {
  std::map<int, Eigen::Vector3d> points;
  for (const BoardPoint& p : boardPoints(board)) points[p.id] = p.p_board;
  for (const auto& v : views) {
    if (!v.found()) continue;
    object.emplace_back();
    image.emplace_back();
    for (const Observation& o : v.points) {
      const Eigen::Vector3d& p = points.at(o.id);
      object.back().emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
      image.back().emplace_back(static_cast<float>(o.px.x()), static_cast<float>(o.px.y()));
    }
  }
}

// The camera as a map from pixels to rays against the truth's, where the board was seen: every
// pixel of a 4 px grid inside the disc (about the truth's principal point) that the observed
// points reach, unprojected through 'est' and projected through 'truth', lands this far from
// itself (worst, px). Past the data the six rational terms extrapolate freely.
double worstRayMapError(const Camera& est, const Camera& truth, const std::vector<ViewObservations>& views,
                        double* disc_px) {
  double reach = 0;
  for (const auto& v : views)
    for (const Observation& o : v.points) reach = std::max(reach, (o.px - Eigen::Vector2d(truth.cx, truth.cy)).norm());
  *disc_px = reach;
  double worst = 0;
  for (double v = 0; v < truth.height; v += 4)
    for (double u = 0; u < truth.width; u += 4) {
      if ((Eigen::Vector2d(u, v) - Eigen::Vector2d(truth.cx, truth.cy)).norm() > reach) continue;
      const auto ray = est.unproject({u, v});
      const auto back = ray ? truth.project(*ray) : std::nullopt;
      if (!back) return std::numeric_limits<double>::infinity();
      worst = std::max(worst, (*back - Eigen::Vector2d(u, v)).norm());
    }
  return worst;
}

// The intrinsic vector's order (kIntrinsicNames) of a camera.
std::array<double, kIntrinsicCount> vectorOf(const Camera& c) {
  return {c.fx, c.fy, c.cx, c.cy, c.skew, c.dist.k1, c.dist.k2, c.dist.p1, c.dist.p2,
          c.dist.k3, c.dist.k4, c.dist.k5, c.dist.k6};
}

// Table 5.1's measure (|delta fx| <= 0.05 px median over seeds, every truth within 3 sigma) for
// the rational model: the thesis board (15 x 11 inner corners), 20 views of exact projections
// plus 0.04 px of noise per seed, solved for fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6 from OpenCV's
// rational initialisation; seed 0 beside cv::calibrateCamera(CALIB_RATIONAL_MODEL) on the same
// points. Measured (calib_tests --gtest_filter=Rational.*): median |delta fx| 0.038 px, fx fy cx
// cy p1 p2 within 2.25 sigma; k1..k6 individually up to 8 sigma off (see below) while the lens
// they make stays within 0.19 px of the truth's over the data; OpenCV's answer on seed 0 equals
// ours to 1e-4 px in fx and to the fourth digit in every term, the same RMS (0.0561 px).
TEST(Rational, IntrinsicsOverSeedsWithinTheirSigmaAndBesideOpenCv) {
  const Camera truth = rationalWitness();
  {
    const auto corner = truth.unproject(Eigen::Vector2d(-0.5, -0.5));
    ASSERT_TRUE(corner.has_value());
    std::printf("image corner %.1f degrees off the axis\n", std::acos(corner->z()) * 180.0 / M_PI);
  }
  const BoardSpec board = testing::thesisBoard(BoardType::kChessboard);
  IntrinsicsOptions options;
  options.locks.rational = true;
  options.joint_covariance = false;
  const std::array<double, kIntrinsicCount> tru = vectorOf(truth);
  std::vector<double> df, map_px;
  double worst_z = 0, worst_k_z = 0;
  std::string worst;
  for (int seed = 0; seed < 8; ++seed) {
    const auto views = projectedViews(truth, board, 20, 300 + seed, 0.04);
    const IntrinsicsResult r = calibrateIntrinsics(views, board, options);
    ASSERT_TRUE(r.covariance_ok) << r.covariance_message;
    ASSERT_TRUE(r.camera.dist.isRational());
    const std::array<double, kIntrinsicCount> est = vectorOf(r.camera);
    df.push_back(std::abs(r.camera.fx - truth.fx));
    double disc_px = 0;
    map_px.push_back(worstRayMapError(r.camera, truth, views, &disc_px));
    std::printf("seed %d: fx %+.4f (sigma %.4f) cx %+.4f (%.4f) k1 %+.5f (%.5f) k4 %+.5f (%.5f) k6 %+.5f (%.5f) "
                "RMS %.4f px, pixel->ray map within %.4f px of the truth's (over %.0f px about the centre)\n",
                seed, est[0] - tru[0], r.sigma[0], est[2] - tru[2], r.sigma[2], est[5] - tru[5], r.sigma[5],
                est[10] - tru[10], r.sigma[10], est[12] - tru[12], r.sigma[12], r.rms_px, map_px.back(), disc_px);
    for (int k = 0; k < kIntrinsicCount; ++k) {
      if (k == 4) continue;  // skew held
      ASSERT_GT(r.sigma[k], 0.0) << kIntrinsicNames[k];
      const double z = std::abs(est[k] - tru[k]) / r.sigma[k];
      // k1 k2 k3 k4 k5 k6: the rational factor's numerator and denominator share a nearly common
      // factor over the image (N (1 + a r^2) / D (1 + a r^2) is the same lens to within the
      // noise), so the six move together along a curved valley (k1 and k4 by the same amount,
      // seed 0: -1.0565 and -1.0570) where the linearised sigma means little: measured up to 8
      // sigma off, while the lens they define is the truth's (map_px). Not asserted one by one.
      if (k >= 5 && k != 7 && k != 8) {
        worst_k_z = std::max(worst_k_z, z);
        continue;
      }
      if (z > worst_z) {
        worst_z = z;
        worst = std::string(kIntrinsicNames[k]) + " seed " + std::to_string(seed);
      }
      EXPECT_LE(z, 3.0) << kIntrinsicNames[k] << " seed " << seed;
    }
    if (seed != 0) continue;
    // OpenCV's rational calibration of the same points, its defaults otherwise.
    std::vector<std::vector<cv::Point3f>> object;
    std::vector<std::vector<cv::Point2f>> image;
    openCvPoints(views, board, object, image);
    cv::Mat K, D;
    std::vector<cv::Mat> rvecs, tvecs;
    const double cv_rms = cv::calibrateCamera(object, image, cv::Size(truth.width, truth.height), K, D, rvecs, tvecs,
                                              cv::CALIB_RATIONAL_MODEL);
    std::printf("  opencv (seed 0): fx %+.4f cx %+.4f k1 %+.5f k4 %+.5f k6 %+.5f RMS %.4f px (ours %.4f)\n",
                K.at<double>(0, 0) - tru[0], K.at<double>(0, 2) - tru[2], D.at<double>(0) - tru[5],
                D.at<double>(5) - tru[10], D.at<double>(7) - tru[12], cv_rms, r.rms_all_px);
    // OpenCV 4.6 returns 14 coefficients (thin prism and tilt held at 0) for an empty D.
    ASSERT_GE(D.total(), 8u);
    for (size_t i = 8; i < D.total(); ++i) EXPECT_EQ(D.at<double>(static_cast<int>(i)), 0.0);
    // The same least-squares problem (no outliers here): the same answer within a tenth of
    // previz's sigma, and the same RMS.
    const double ocv[] = {K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2), K.at<double>(1, 2)};
    for (int k = 0; k < 4; ++k) EXPECT_NEAR(est[k], ocv[k], 0.1 * r.sigma[k]) << kIntrinsicNames[k];
    EXPECT_NEAR(r.rms_all_px, cv_rms, 0.002);
  }
  std::printf("median |delta fx| %.4f px over %zu seeds; worst |error| / sigma %.2f (%s) over fx fy cx cy p1 p2, %.2f "
              "over k1..k6; pixel->ray map: median %.4f px, worst %.4f px off the truth's\n",
              median(df), df.size(), worst_z, worst.c_str(), worst_k_z, median(map_px),
              *std::max_element(map_px.begin(), map_px.end()));
  EXPECT_LE(median(df), 0.05);
  // Measured: median 0.115 px, worst 0.185 px (seed 3), at the rim of the data where the last
  // board corners are; 0.04 px of noise per coordinate.
  EXPECT_LE(median(map_px), 0.15);
  for (double m : map_px) EXPECT_LE(m, 0.25);
}

// Real pixels: OpenCV's left sample camera (13 views, 9 x 6 inner corners), calibrated with the
// rational model by previz and by cv::calibrateCamera(CALIB_RATIONAL_MODEL) on the same
// detections. This webcam's lens is mild: k1..k6 are poorly determined by 13 views (measured
// k1 -13.6 +- 6.3, k2 68.6 +- 48, k5 64.8 +- 47: numerator and denominator trade off), so what is
// asserted is what is meaningful: fx fy cx cy agree within 3 sigma (measured: every figure equal
// to OpenCV's to 1e-3 px; fx 533.383 +- 0.374 vs 533.551 +- 0.359 with the plain model), the RMS
// is OpenCV's or better (0.1592 px both; plain model 0.1600), and the two lenses (each with its
// own K) map the image to the same rays (1.4e-4 px apart).
TEST(Rational, RealChessboardBesideOpenCvsRationalCalibration) {
  const std::filesystem::path dir = std::filesystem::path(PREVIZ_SHARED_DATA) / "opencv-chessboard";
  std::vector<std::filesystem::path> files;
  if (std::filesystem::is_directory(dir))
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind("left", 0) == 0 && entry.path().extension() == ".jpg") files.push_back(entry.path());
    }
  std::sort(files.begin(), files.end());
  ASSERT_EQ(files.size(), 13u) << "expected 13 images " << (dir / "left*.jpg").string();
  const BoardSpec board = previz::test::opencvSampleBoard();
  std::vector<ViewObservations> views;
  for (const auto& f : files) {
    const cv::Mat image = readImage(f, cv::IMREAD_GRAYSCALE);
    ViewObservations v = detectBoard(image, board, {}, f.filename().string());
    v.image_size = image.size();
    views.push_back(v);
  }
  IntrinsicsOptions options;
  options.locks.rational = true;
  const IntrinsicsResult ours = calibrateIntrinsics(views, board, options);
  const IntrinsicsResult plain = calibrateIntrinsics(views, board);

  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  openCvPoints(views, board, object, image);
  cv::Mat K, D;
  std::vector<cv::Mat> rvecs, tvecs;
  const double cv_rms =
      cv::calibrateCamera(object, image, views.front().image_size, K, D, rvecs, tvecs, cv::CALIB_RATIONAL_MODEL);
  const Camera& c = ours.camera;
  std::printf("\nReal data, rational model (%zu images, %zu with the board): ours vs "
              "cv::calibrateCamera(CALIB_RATIONAL_MODEL) on the same detections\n",
              views.size(), object.size());
  std::printf("  %-7s %8s %8s %8s %8s %9s %9s %9s %9s %9s %9s %8s\n", "", "fx", "fy", "cx", "cy", "k1", "k2", "k3",
              "k4", "k5", "k6", "RMS px");
  std::printf("  %-7s %8.3f %8.3f %8.3f %8.3f %9.4f %9.4f %9.4f %9.4f %9.4f %9.4f %8.4f (all %.4f, %d rejected)\n",
              "ours", c.fx, c.fy, c.cx, c.cy, c.dist.k1, c.dist.k2, c.dist.k3, c.dist.k4, c.dist.k5, c.dist.k6,
              ours.rms_px, ours.rms_all_px, ours.points_rejected);
  std::printf("  %-7s %8.3f %8.3f %8.3f %8.3f %9.4f %9.4f %9.4f %9.4f %9.4f %9.4f\n", "sigma", ours.sigma[0],
              ours.sigma[1], ours.sigma[2], ours.sigma[3], ours.sigma[5], ours.sigma[6], ours.sigma[9], ours.sigma[10],
              ours.sigma[11], ours.sigma[12]);
  std::printf("  %-7s %8.3f %8.3f %8.3f %8.3f %9.4f %9.4f %9.4f %9.4f %9.4f %9.4f %8.4f\n", "opencv",
              K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2), K.at<double>(1, 2), D.at<double>(0),
              D.at<double>(1), D.at<double>(4), D.at<double>(5), D.at<double>(6), D.at<double>(7), cv_rms);
  std::printf("  plain Brown-Conrady (ours): fx %.3f +- %.3f, RMS %.4f px (all %.4f)\n", plain.camera.fx,
              plain.sigma[0], plain.rms_px, plain.rms_all_px);

  // The two rational lenses as maps from pixels to rays: our ray of each pixel of a 10 px grid,
  // projected through OpenCV's camera, lands this far from the pixel.
  Camera theirs = c;
  theirs.fx = K.at<double>(0, 0);
  theirs.fy = K.at<double>(1, 1);
  theirs.cx = K.at<double>(0, 2);
  theirs.cy = K.at<double>(1, 2);
  theirs.dist = {D.at<double>(0), D.at<double>(1), D.at<double>(2), D.at<double>(3),
                 D.at<double>(4), D.at<double>(5), D.at<double>(6), D.at<double>(7)};
  double worst_px = 0;
  for (double v = 0; v < c.height; v += 10)
    for (double u = 0; u < c.width; u += 10) {
      const auto ray = c.unproject({u, v});
      ASSERT_TRUE(ray) << u << ", " << v;
      const auto back = theirs.project(*ray);
      ASSERT_TRUE(back) << u << ", " << v;
      worst_px = std::max(worst_px, (*back - Eigen::Vector2d(u, v)).norm());
    }
  std::printf("  our rays through OpenCV's rational camera: worst %.2e px over the image\n", worst_px);

  EXPECT_EQ(object.size(), 13u);
  EXPECT_LE(ours.rms_all_px, cv_rms + 0.01);
  // More terms fit the same corners no worse.
  EXPECT_LE(ours.rms_all_px, plain.rms_all_px + 1e-4);
  const double est[] = {c.fx, c.fy, c.cx, c.cy};
  const double ocv[] = {K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2), K.at<double>(1, 2)};
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(est[k], ocv[k], 3 * ours.sigma[k]) << kIntrinsicNames[k];
  // Measured 0.000 px (the two solves land on the same minimum, every term within 1e-4 of
  // its sigma-sized value): a hundredth of a pixel is what "the same lens" means here.
  EXPECT_LE(worst_px, 0.01);
}

}  // namespace
}  // namespace previz::calib
