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

#include "core/camera.h"
#include "core/lens_model.h"

namespace previz {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A 190-degree-class fisheye as OpenCV's and Kalibr's calibrations report them.
constexpr double kKb[4] = {-0.0131, 0.0204, -0.0173, 0.0039};
constexpr double kBrown[8] = {-0.28, 0.11, 0.0009, -0.0012, -0.02, 0, 0, 0};  // k1 k2 p1 p2 k3 (k4..k6 = 0)
// A wide lens in OpenCV's rational model (CALIB_RATIONAL_MODEL), of the size its calibrations of
// wide lenses report: numerator and denominator terms of the same order, which nearly cancel
// (radial = 1 - 0.36 r^2 + ... near the axis, a strong barrel).
constexpr double kRational[8] = {1.85, 0.62, 0.0008, -0.0011, 0.021, 2.21, 1.12, 0.098};

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
    lens::brownDistort(kBrown[0], kBrown[1], kBrown[2], kBrown[3], kBrown[4], 0.0, 0.0, 0.0, pts[i].x, pts[i].y, xd, yd);
    worst = std::max(worst, std::hypot(xd - theirs[i].x, yd - theirs[i].y));
  }
  EXPECT_LT(worst, 1e-12);
}

// k4 = k5 = k6 = 0 is the plain model to the last bit: the forward map, its Jacobian and the
// coefficient Jacobian equal the five-term formulas as they were written before the rational
// terms (EXPECT_EQ on doubles, over 2000 points out to r = 1.4).
TEST(LensModel, ZeroRationalTermsAreThePlainModelBitForBit) {
  const double k1 = kBrown[0], k2 = kBrown[1], p1 = kBrown[2], p2 = kBrown[3], k3 = kBrown[4];
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 2000; ++i) {
    const double x = u(rng), y = u(rng);
    // The plain model as lens_model.h had it.
    const double x2 = x * x, y2 = y * y, xy = x * y, r2 = x2 + y2;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double slope = k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3));
    const double tx = 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x), ty = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy;
    double xd, yd, j00, j01, j11;
    lens::brownDistortWithJacobian(k1, k2, p1, p2, k3, 0.0, 0.0, 0.0, x, y, xd, yd, j00, j01, j11);
    ASSERT_EQ(xd, x * radial + tx);
    ASSERT_EQ(yd, y * radial + ty);
    ASSERT_EQ(j00, radial + 2.0 * x2 * slope + 2.0 * p1 * y + 6.0 * p2 * x);
    ASSERT_EQ(j01, 2.0 * xy * slope + 2.0 * p1 * x + 2.0 * p2 * y);
    ASSERT_EQ(j11, radial + 2.0 * y2 * slope + 6.0 * p1 * y + 2.0 * p2 * x);
    double a, b;
    lens::brownDistort(k1, k2, p1, p2, k3, 0.0, 0.0, 0.0, x, y, a, b);
    ASSERT_EQ(a, xd);
    ASSERT_EQ(b, yd);
    // The division-free path Camera takes for a plain lens: the same bits.
    double c, e, q00, q01, q11;
    lens::brownDistortWithJacobian<false>(k1, k2, p1, p2, k3, 0.0, 0.0, 0.0, x, y, c, e, q00, q01, q11);
    ASSERT_EQ(c, xd);
    ASSERT_EQ(e, yd);
    ASSERT_EQ(q00, j00);
    ASSERT_EQ(q01, j01);
    ASSERT_EQ(q11, j11);
    double J[16];
    lens::brownCoefficientJacobian(k1, k2, k3, 0.0, 0.0, 0.0, x, y, J);
    const double r4 = r2 * r2;
    const double old[10] = {x * r2, x * r4, 2.0 * xy, r2 + 2.0 * x * x, x * r4 * r2,
                            y * r2, y * r4, r2 + 2.0 * y * y, 2.0 * xy, y * r4 * r2};
    for (int c = 0; c < 5; ++c) {
      ASSERT_EQ(J[c], old[c]) << "column " << c;
      ASSERT_EQ(J[8 + c], old[5 + c]) << "column " << c;
    }
  }
}

// OpenCV's rational model: Camera::project equals cv::projectPoints with the 8-term D to 1e-9 px
// over a 1920 x 1080 image (f = 1000 px, a 49 x 28 grid of ideal directions out to 52 degrees off
// the axis horizontally and 37 vertically, most of them landing in the image).
TEST(LensModel, RationalProjectionIsOpenCvsRationalModelWithinANanoPixel) {
  Camera cam;
  cam.name = "wide";
  cam.width = 1920;
  cam.height = 1080;
  cam.fx = 1000.5;
  cam.fy = 999.25;
  cam.cx = 961.3;
  cam.cy = 538.7;
  cam.dist = {kRational[0], kRational[1], kRational[2], kRational[3], kRational[4], kRational[5], kRational[6], kRational[7]};
  ASSERT_NO_THROW(cam.validate());
  std::vector<cv::Point3d> pts;
  std::vector<Eigen::Vector2d> ours;
  for (int j = 0; j < 28; ++j)
    for (int i = 0; i < 49; ++i) {
      const Eigen::Vector3d p(-1.3 + 2.6 * i / 48.0, -0.75 + 1.5 * j / 27.0, 1.0);
      const auto px = cam.project(p);
      ASSERT_TRUE(px) << p.transpose();
      pts.emplace_back(p.x(), p.y(), p.z());
      ours.push_back(*px);
    }
  const cv::Mat K = (cv::Mat_<double>(3, 3) << cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
  const cv::Mat D(1, 8, CV_64F, const_cast<double*>(kRational));
  std::vector<cv::Point2d> theirs;
  cv::projectPoints(pts, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, theirs);
  double worst = 0;
  int in_image = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    worst = std::max(worst, (ours[i] - Eigen::Vector2d(theirs[i].x, theirs[i].y)).norm());
    in_image += cam.inImage(ours[i]);
  }
  std::printf("rational projection vs cv::projectPoints (8-term D): %zu points (%d in the image), worst %.2e px\n",
              pts.size(), in_image, worst);
  EXPECT_LT(worst, 1e-9);
  EXPECT_GT(in_image, 1000);
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
    // Brown-Conrady, plain and rational: coefficients in OpenCV's order k1 k2 p1 p2 k3 k4 k5 k6.
    for (const double* K : {kBrown, kRational}) {
      lens::brownDistortWithJacobian(K[0], K[1], K[2], K[3], K[4], K[5], K[6], K[7], x, y, xd, yd, j00, j01, j11);
      auto brown = [&](double px, double py, const double* k) {
        double a, b;
        lens::brownDistort(k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7], px, py, a, b);
        return Eigen::Vector2d(a, b);
      };
      const Eigen::Vector2d dx = (brown(x + h, y, K) - brown(x - h, y, K)) / (2 * h);
      const Eigen::Vector2d dy = (brown(x, y + h, K) - brown(x, y - h, K)) / (2 * h);
      EXPECT_NEAR(j00, dx.x(), 1e-7);
      EXPECT_NEAR(j01, dx.y(), 1e-7);
      EXPECT_NEAR(j01, dy.x(), 1e-7);
      EXPECT_NEAR(j11, dy.y(), 1e-7);
      double Jk[16];
      lens::brownCoefficientJacobian(K[0], K[1], K[4], K[5], K[6], K[7], x, y, Jk);
      for (int c = 0; c < 8; ++c) {
        double kp[8], km[8];
        for (int i = 0; i < 8; ++i) kp[i] = km[i] = K[i];
        kp[c] += h;
        km[c] -= h;
        const Eigen::Vector2d d = (brown(x, y, kp) - brown(x, y, km)) / (2 * h);
        // Relative to the column's size: at r = 2 the r^6 columns reach ~100.
        const double tol = 1e-7 * std::max(1.0, std::abs(d.x()) + std::abs(d.y()));
        EXPECT_NEAR(Jk[c], d.x(), tol) << "brown coefficient " << c << (K == kRational ? " (rational)" : "");
        EXPECT_NEAR(Jk[8 + c], d.y(), tol) << "brown coefficient " << c << (K == kRational ? " (rational)" : "");
      }
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
    double Jk[8];
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

// Issue 34: the inverse of a strong rational lens (kRational, f = 1000 px over 1920 x 1080: the
// corners see 61 degrees off the axis, where the radial factor is 0.61) within 1e-6 px over every
// pixel of a 2 px grid, both methods reporting convergence; Newton's iterations reported.
TEST(LensModel, RationalInverseRoundTripBelowAMicroPixelOverTheImage) {
  Camera cam;
  cam.name = "wide";
  cam.width = 1920;
  cam.height = 1080;
  cam.fx = cam.fy = 1000;
  cam.cx = 959.5;
  cam.cy = 539.5;
  cam.dist = {kRational[0], kRational[1], kRational[2], kRational[3], kRational[4], kRational[5], kRational[6], kRational[7]};
  const InverseDistortion inverse(cam.dist);
  for (const InverseMethod method : {InverseMethod::kNewton, InverseMethod::kFixedPoint}) {
    InverseOptions options;
    options.method = method;
    options.max_iterations = 200;
    double worst_px = 0;
    int points = 0, max_iterations = 0, not_converged = 0;
    for (double v = 0; v < cam.height; v += 2)
      for (double u = 0; u < cam.width; u += 2) {
        const Eigen::Vector2d xd = cam.pixelToNormalized({u, v});
        const InverseResult r = inverse.solve(xd, options);
        if (!r.ok()) {
          ++not_converged;
          continue;
        }
        worst_px = std::max(worst_px, (cam.normalizedToPixel(cam.distort(r.point)) - Eigen::Vector2d(u, v)).norm());
        max_iterations = std::max(max_iterations, r.iterations);
        ++points;
      }
    std::printf("rational inverse (%s): %d pixels, %d not converged, worst round trip %.2e px, at most %d iterations; "
                "turning radius %g\n",
                toString(method), points, not_converged, worst_px, max_iterations, cam.maxInvertibleRadius());
    EXPECT_EQ(not_converged, 0) << toString(method);
    EXPECT_LT(worst_px, 1e-6) << toString(method);
  }
}

// Where the rational radial map r -> r radial(r^2) stops increasing, against a brute-force scan
// of it (1e6 steps): a lens that turns (barrel numerator, weak denominator), and one whose
// denominator reaches 0 first (a pole: radial = 1 / (1 - r^2), the domain ends at r = 1). Points
// past it do not project; the inverse of a point beyond the image of the domain says "not
// invertible".
TEST(LensModel, RationalTurningRadiusIsWhereTheRadialMapStopsIncreasing) {
  Camera cam;
  cam.width = 1000;
  cam.height = 1000;
  cam.fx = cam.fy = 500;
  cam.cx = cam.cy = 499.5;
  cam.dist = {-0.6, 0.05, 0, 0, 0.01, 0.2, -0.03, 0.004};
  auto radial_map = [&](double r) { return cam.distort({r, 0.0}).x(); };
  double scan = std::numeric_limits<double>::infinity();
  const double step = 4.0 / 1e6;
  for (int i = 1; i <= 1000000; ++i)
    if (!(radial_map(i * step) > radial_map((i - 1) * step))) {
      scan = (i - 1) * step;
      break;
    }
  const double r_max = cam.maxInvertibleRadius();
  std::printf("rational turning radius %.9f (scan %.6f)\n", r_max, scan);
  ASSERT_TRUE(std::isfinite(scan));
  EXPECT_NEAR(r_max, scan, 2 * step);
  EXPECT_TRUE(cam.project({0.99 * r_max, 0, 1}));
  EXPECT_FALSE(cam.project({1.01 * r_max, 0, 1}));
  const double edge = radial_map(r_max);
  EXPECT_EQ(cam.undistort({0.98 * edge, 0}).status, InverseStatus::kConverged);
  EXPECT_EQ(cam.undistort({1.02 * edge, 0}).status, InverseStatus::kNotInvertible);

  cam.dist = {0, 0, 0, 0, 0, -1.0, 0, 0};  // radial = 1 / (1 - r^2)
  EXPECT_NEAR(cam.maxInvertibleRadius(), 1.0, 1e-12);
  EXPECT_TRUE(cam.project({0.999, 0, 1}));
  EXPECT_FALSE(cam.project({1.001, 0, 1}));
  // Increasing without bound up to the pole: every distorted radius has its preimage.
  const InverseResult far = cam.undistort({50.0, 0.0});
  EXPECT_EQ(far.status, InverseStatus::kConverged);
  EXPECT_NEAR(far.point.x(), (-1 + std::sqrt(1 + 4 * 50.0 * 50.0)) / (2 * 50.0), 1e-12);  // r / (1 - r^2) = 50

  // A rational lens that never turns (kRational: radial -> k3 / k6 > 0): +inf.
  cam.dist = {kRational[0], kRational[1], kRational[2], kRational[3], kRational[4], kRational[5], kRational[6], kRational[7]};
  EXPECT_TRUE(std::isinf(cam.maxInvertibleRadius()));
}

}  // namespace
}  // namespace previz
