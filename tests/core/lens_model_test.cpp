// core/lens_model.h: each lens model defined once. Against OpenCV's own implementations
// (cv::projectPoints for Brown–Conrady, cv::fisheye for Kannala–Brandt), the Jacobians against
// central differences, and Kannala–Brandt's inverse over a whole fisheye image circle.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <opencv2/calib3d.hpp>

#include "core/lens_model.h"

namespace previz {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A 190-degree-class fisheye as OpenCV's and Kalibr's calibrations report them.
constexpr double kKb[4] = {-0.0131, 0.0204, -0.0173, 0.0039};
constexpr double kBrown[5] = {-0.28, 0.11, 0.0009, -0.0012, -0.02};  // k1 k2 p1 p2 k3

TEST(LensModel, BrownConradyIsOpenCvs) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  std::vector<cv::Point3d> pts;
  for (int i = 0; i < 200; ++i) pts.emplace_back(u(rng), u(rng), 1.0);
  std::vector<cv::Point2d> theirs;
  const cv::Mat K = cv::Mat::eye(3, 3, CV_64F), dist = (cv::Mat_<double>(1, 5) << kBrown[0], kBrown[1], kBrown[2], kBrown[3], kBrown[4]);
  cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, dist, theirs);
  double worst = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    double xd, yd;
    lens::brownDistort(kBrown[0], kBrown[1], kBrown[2], kBrown[3], kBrown[4], pts[i].x, pts[i].y, xd, yd);
    worst = std::max(worst, std::hypot(xd - theirs[i].x, yd - theirs[i].y));
  }
  EXPECT_LT(worst, 1e-12);
}

TEST(LensModel, KannalaBrandtIsOpenCvsFisheye) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> angle(0, 2 * kPi), off_axis(0, 85 * kPi / 180);
  std::vector<cv::Point2d> ideal;
  for (int i = 0; i < 200; ++i) {
    const double a = angle(rng), r = std::tan(off_axis(rng));
    ideal.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  std::vector<cv::Point2d> theirs;
  cv::fisheye::distortPoints(ideal, theirs, cv::Matx33d::eye(), cv::Vec4d(kKb[0], kKb[1], kKb[2], kKb[3]));
  double worst = 0;
  for (size_t i = 0; i < ideal.size(); ++i) {
    double xd, yd;
    lens::kannalaBrandtDistort(kKb[0], kKb[1], kKb[2], kKb[3], ideal[i].x, ideal[i].y, xd, yd);
    worst = std::max(worst, std::hypot(xd - theirs[i].x, yd - theirs[i].y));
  }
  EXPECT_LT(worst, 1e-12);
}

// Analytic Jacobians (point and coefficients) against central differences.
TEST(LensModel, JacobiansMatchCentralDifferences) {
  const double h = 1e-6;
  for (const auto& [x, y] : std::vector<std::pair<double, double>>{{0.3, -0.2}, {-0.5, 0.45}, {1e-5, 2e-5}, {1.8, 0.9}}) {
    double xd, yd, j00, j01, j11;
    lens::brownDistortWithJacobian(kBrown[0], kBrown[1], kBrown[2], kBrown[3], kBrown[4], x, y, xd, yd, j00, j01, j11);
    auto brown = [&](double px, double py, const double* k) {
      double a, b;
      lens::brownDistort(k[0], k[1], k[2], k[3], k[4], px, py, a, b);
      return Eigen::Vector2d(a, b);
    };
    const Eigen::Vector2d dx = (brown(x + h, y, kBrown) - brown(x - h, y, kBrown)) / (2 * h);
    const Eigen::Vector2d dy = (brown(x, y + h, kBrown) - brown(x, y - h, kBrown)) / (2 * h);
    EXPECT_NEAR(j00, dx.x(), 1e-7);
    EXPECT_NEAR(j01, dx.y(), 1e-7);
    EXPECT_NEAR(j01, dy.x(), 1e-7);
    EXPECT_NEAR(j11, dy.y(), 1e-7);
    double Jk[10];
    lens::brownCoefficientJacobian(x, y, Jk);
    for (int c = 0; c < 5; ++c) {
      double kp[5], km[5];
      for (int i = 0; i < 5; ++i) kp[i] = km[i] = kBrown[i];
      kp[c] += h;
      km[c] -= h;
      const Eigen::Vector2d d = (brown(x, y, kp) - brown(x, y, km)) / (2 * h);
      EXPECT_NEAR(Jk[c], d.x(), 1e-7) << "brown coefficient " << c;
      EXPECT_NEAR(Jk[5 + c], d.y(), 1e-7) << "brown coefficient " << c;
    }

    lens::kannalaBrandtDistortWithJacobian(kKb[0], kKb[1], kKb[2], kKb[3], x, y, xd, yd, j00, j01, j11);
    auto kb = [&](double px, double py, const double* k) {
      double a, b;
      lens::kannalaBrandtDistort(k[0], k[1], k[2], k[3], px, py, a, b);
      return Eigen::Vector2d(a, b);
    };
    const Eigen::Vector2d ex = (kb(x + h, y, kKb) - kb(x - h, y, kKb)) / (2 * h);
    const Eigen::Vector2d ey = (kb(x, y + h, kKb) - kb(x, y - h, kKb)) / (2 * h);
    EXPECT_NEAR(j00, ex.x(), 1e-7);
    EXPECT_NEAR(j01, ex.y(), 1e-7);
    EXPECT_NEAR(j01, ey.x(), 1e-7);
    EXPECT_NEAR(j11, ey.y(), 1e-7);
    lens::kannalaBrandtCoefficientJacobian(x, y, Jk);
    for (int c = 0; c < 4; ++c) {
      double kp[4], km[4];
      for (int i = 0; i < 4; ++i) kp[i] = km[i] = kKb[i];
      kp[c] += h;
      km[c] -= h;
      const Eigen::Vector2d d = (kb(x, y, kp) - kb(x, y, km)) / (2 * h);
      EXPECT_NEAR(Jk[c], d.x(), 1e-7) << "kb coefficient " << c;
      EXPECT_NEAR(Jk[4 + c], d.y(), 1e-7) << "kb coefficient " << c;
    }
  }
}

// Issue 34 item 1: the inverse round trip within 1e-6 px over the whole image circle of a fisheye
// witness (f = 330 px, 1280 x 960, the circle reaching 88 degrees off the axis: a 176-degree
// field of view), every pixel of a 2 px grid; beyond the lens' turning angle, "not invertible".
TEST(LensModel, KannalaBrandtInverseRoundTripBelowAMicroPixelOverTheImageCircle) {
  const double f = 330, cx = 639.5, cy = 479.5;
  const double max_theta = lens::kannalaBrandtMaxTheta(kKb[0], kKb[1], kKb[2], kKb[3]);
  const double circle_px = f * lens::kannalaBrandtTheta(kKb[0], kKb[1], kKb[2], kKb[3], 88 * kPi / 180);
  double worst_px = 0;
  int points = 0, max_iterations = 0;
  for (double v = 0; v < 960; v += 2)
    for (double u = 0; u < 1280; u += 2) {
      const double xd = (u - cx) / f, yd = (v - cy) / f;
      if (std::hypot(u - cx, v - cy) > circle_px) continue;
      const lens::KannalaBrandtInverse inv = lens::kannalaBrandtUndistort(kKb[0], kKb[1], kKb[2], kKb[3], xd, yd, max_theta);
      ASSERT_EQ(inv.status, InverseStatus::kConverged) << "pixel " << u << ", " << v;
      double x2, y2;
      lens::kannalaBrandtDistort(kKb[0], kKb[1], kKb[2], kKb[3], inv.x, inv.y, x2, y2);
      worst_px = std::max(worst_px, f * std::hypot(x2 - xd, y2 - yd));
      max_iterations = std::max(max_iterations, inv.iterations);
      ++points;
    }
  std::printf("kannala-brandt inverse: %d pixels within %.1f px of the centre (88 deg), worst round trip %.2e px, "
              "at most %d iterations; turning angle %.1f deg\n",
              points, circle_px, worst_px, max_iterations, max_theta * 180 / kPi);
  EXPECT_GT(points, 180000);  // pi 494.8^2 / 4
  EXPECT_LT(worst_px, 1e-6);
  // A lens that turns: k1 = -0.5 makes theta_d fall after ~55 degrees; beyond its image, no inverse.
  const double turn = lens::kannalaBrandtMaxTheta(-0.5, 0, 0, 0);
  EXPECT_NEAR(turn, std::sqrt(1 / 1.5), 1e-9);  // 1 - 1.5 theta^2 = 0
  const double edge = lens::kannalaBrandtTheta(-0.5, 0.0, 0.0, 0.0, turn);
  EXPECT_EQ(lens::kannalaBrandtUndistort(-0.5, 0, 0, 0, edge * 1.01, 0, turn).status, InverseStatus::kNotInvertible);
  EXPECT_EQ(lens::kannalaBrandtUndistort(-0.5, 0, 0, 0, edge * 0.99, 0, turn).status, InverseStatus::kConverged);
}

}  // namespace
}  // namespace previz
