// Camera model: forward projection against OpenCV, Jacobian, turning radius, conventions.
#include "core/camera.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "core/error.h"

namespace previz {
namespace {

Camera randomCamera(std::mt19937& rng, bool with_skew) {
  std::uniform_real_distribution<double> f(300, 2000), c(-40, 40), k1(-0.5, 1.0), k2(-0.3, 0.3),
      p(-0.01, 0.01), k3(-0.1, 0.1), s(-5, 5);
  Camera cam;
  cam.name = "random";
  cam.width = 1280;
  cam.height = 720;
  cam.fx = f(rng);
  cam.fy = cam.fx * std::uniform_real_distribution<double>(0.9, 1.1)(rng);
  cam.cx = 639.5 + c(rng);
  cam.cy = 359.5 + c(rng);
  cam.skew = with_skew ? s(rng) : 0.0;
  cam.dist = {k1(rng), k2(rng), p(rng), p(rng), k3(rng)};
  return cam;
}

// OpenCV's projectPoints ignores K(0,1), so skewed cameras are checked through OpenCV's
// distortion in normalized units (identity K) followed by the full K.
TEST(Camera, ProjectMatchesOpenCvProjectPointsWithinNanoPixel) {
  std::mt19937 rng(7);
  double max_err = 0, max_err_skew = 0;
  int compared = 0, generated = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const bool with_skew = trial % 3 == 2;
    const Camera cam = randomCamera(rng, with_skew);
    std::uniform_real_distribution<double> xy(-0.9, 0.9), z(0.3, 20);
    std::vector<cv::Point3d> pts;
    std::vector<Eigen::Vector2d> ours;
    for (int i = 0; i < 500; ++i) {
      const double zz = z(rng);
      const Eigen::Vector3d p(xy(rng) * zz, xy(rng) * 0.6 * zz, zz);
      ++generated;
      const auto px = cam.project(p);
      if (!px) continue;  // past this lens's turning radius: OpenCV would fold it back
      pts.emplace_back(p.x(), p.y(), p.z());
      ours.push_back(*px);
    }
    compared += static_cast<int>(pts.size());
    const cv::Mat D = (cv::Mat_<double>(1, 5) << cam.dist.k1, cam.dist.k2, cam.dist.p1, cam.dist.p2, cam.dist.k3);
    const cv::Mat zero = cv::Mat::zeros(3, 1, CV_64F);
    std::vector<cv::Point2d> cv_px;
    if (!with_skew) {
      const cv::Mat K = (cv::Mat_<double>(3, 3) << cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
      cv::projectPoints(pts, zero, zero, K, D, cv_px);
      for (size_t i = 0; i < pts.size(); ++i)
        max_err = std::max(max_err, (ours[i] - Eigen::Vector2d(cv_px[i].x, cv_px[i].y)).norm());
    } else {
      cv::projectPoints(pts, zero, zero, cv::Mat::eye(3, 3, CV_64F), D, cv_px);
      for (size_t i = 0; i < pts.size(); ++i) {
        const Eigen::Vector3d h = cam.K() * Eigen::Vector3d(cv_px[i].x, cv_px[i].y, 1.0);
        max_err_skew = std::max(max_err_skew, (ours[i] - h.head<2>()).norm());
      }
    }
  }
  std::cout << "projectPoints: " << compared << "/" << generated << " points compared, max |diff| = " << max_err
            << " px (skew 0), " << max_err_skew << " px (skewed)\n";
  EXPECT_GT(compared, generated * 8 / 10);
  EXPECT_LE(max_err, 1e-9);
  EXPECT_LE(max_err_skew, 1e-9);
}

TEST(Camera, PixelToNormalizedInvertsNormalizedToPixelWithSkew) {
  std::mt19937 rng(3);
  for (int i = 0; i < 20; ++i) {
    const Camera cam = randomCamera(rng, true);
    const Eigen::Vector2d xd(0.31, -0.27);
    EXPECT_LE((cam.pixelToNormalized(cam.normalizedToPixel(xd)) - xd).norm(), 1e-15);
    const Eigen::Vector3d h = cam.K() * Eigen::Vector3d(xd.x(), xd.y(), 1.0);
    EXPECT_LE((cam.normalizedToPixel(xd) - h.head<2>()).norm(), 1e-9);
  }
}

TEST(Camera, DistortJacobianMatchesCentralDifferences) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> xy(-0.6, 0.6);
  double worst = 0;
  for (int trial = 0; trial < 50; ++trial) {
    const Camera cam = randomCamera(rng, false);
    const Eigen::Vector2d x(xy(rng), xy(rng));
    const Eigen::Matrix2d J = cam.distortJacobian(x);
    const double h = 1e-6;
    Eigen::Matrix2d Jn;
    for (int k = 0; k < 2; ++k) {
      Eigen::Vector2d e = Eigen::Vector2d::Zero();
      e[k] = h;
      Jn.col(k) = (cam.distort(x + e) - cam.distort(x - e)) / (2 * h);
    }
    worst = std::max(worst, (J - Jn).cwiseAbs().maxCoeff());
  }
  EXPECT_LE(worst, 1e-8);  // central differences: O(h^2) + rounding / h
}

// r_max is where d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] = 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 = 0.
TEST(Camera, MaxInvertibleRadiusIsTheTurningPointOfTheRadialMap) {
  Camera cam;
  cam.dist = {-0.5, 0, 0, 0, 0};
  EXPECT_NEAR(cam.maxInvertibleRadius(), std::sqrt(1.0 / 1.5), 1e-15);
  cam.dist = {-0.3, -0.1, 0, 0, 0};  // 1 - 0.9 s - 0.5 s^2 = 0
  EXPECT_NEAR(cam.maxInvertibleRadius(), std::sqrt((-0.9 + std::sqrt(0.81 + 2.0)) / 1.0), 1e-15);
  cam.dist = {1.0, -0.3, 0, 0, 0};  // 1 + 3 s - 1.5 s^2 = 0
  EXPECT_NEAR(cam.maxInvertibleRadius(), std::sqrt((3.0 + std::sqrt(9.0 + 6.0)) / 3.0), 1e-14);
  // Monotone lenses never turn.
  for (const Distortion& d : {Distortion{0.2, 0.1, 0, 0, 0}, Distortion{-0.5, 0.3, 0, 0, 0},
                             Distortion{0, 0, 0.01, 0.01, 0}}) {
    cam.dist = d;
    EXPECT_TRUE(std::isinf(cam.maxInvertibleRadius())) << d.k1 << " " << d.k2;
  }
  // A k3 lens whose slope has an interior minimum: compare with a dense scan of r radial(r).
  cam.dist = {-0.2, 0.05, 0, 0, -0.02};
  const double rmax = cam.maxInvertibleRadius();
  double best_r = 0, best_g = -1;
  for (double r = 0; r < 3; r += 1e-5) {
    const double g = cam.distort({r, 0}).x();
    if (g > best_g) best_g = g, best_r = r;
    else break;
  }
  EXPECT_NEAR(rmax, best_r, 2e-5);
  // project() refuses points just past it and accepts points just inside.
  cam.width = 100, cam.height = 100, cam.fx = cam.fy = 50, cam.cx = cam.cy = 49.5;
  EXPECT_TRUE(cam.project({rmax * (1 - 1e-9), 0, 1}).has_value());
  EXPECT_FALSE(cam.project({rmax * (1 + 1e-9), 0, 1}).has_value());
  EXPECT_FALSE(cam.project({0, 2 * rmax, 1}).has_value());
}

TEST(Camera, ProjectRejectsPointsBehindOrOnTheCameraPlane) {
  Camera cam;
  cam.width = 64, cam.height = 48, cam.fx = cam.fy = 50, cam.cx = 31.5, cam.cy = 23.5;
  EXPECT_FALSE(cam.project({0, 0, -1}).has_value());
  EXPECT_FALSE(cam.project({0.1, 0, 0}).has_value());
  const auto px = cam.project({0, 0, 2});
  ASSERT_TRUE(px.has_value());
  EXPECT_EQ(*px, Eigen::Vector2d(31.5, 23.5));
}

TEST(Camera, UnprojectGivesUnitRayThroughThePixel) {
  std::mt19937 rng(5);
  const Camera cam = randomCamera(rng, true);
  for (const Eigen::Vector2d& px : {Eigen::Vector2d(0, 0), Eigen::Vector2d(640, 360), Eigen::Vector2d(1279, 719)}) {
    const auto ray = cam.unproject(px);
    // The random lens may fold before the corners; the centre is always invertible.
    if (px.x() == 640) {
      ASSERT_TRUE(ray.has_value());
    }
    if (!ray) continue;
    EXPECT_NEAR(ray->norm(), 1.0, 1e-15);
    EXPECT_GT(ray->z(), 0.0);
    const auto back = cam.project(*ray * 3.7);
    ASSERT_TRUE(back.has_value());
    EXPECT_LE((*back - px).norm(), 1e-6);
  }
}

TEST(Camera, ZeroDistortionUndistortIsTheIdentityInZeroIterations) {
  Camera cam;
  const InverseResult r = cam.undistort({0.3, -0.2});
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.iterations, 0);
  EXPECT_EQ(r.point, Eigen::Vector2d(0.3, -0.2));
}

// c' = (c + 0.5) s - 0.5: a world point lands on the same place of the picture at any size.
TEST(Camera, ScaledCameraKeepsThePixelCentreConvention) {
  std::mt19937 rng(9);
  const Camera cam = randomCamera(rng, true);
  const Camera half = cam.scaled(0.5, 0.5);
  EXPECT_EQ(half.width, 640);
  EXPECT_EQ(half.height, 360);
  const Eigen::Vector3d p(0.2, -0.1, 2.0);
  const auto a = cam.project(p), b = half.project(p);
  ASSERT_TRUE(a && b);
  EXPECT_LE(((*a + Eigen::Vector2d(0.5, 0.5)) * 0.5 - Eigen::Vector2d(0.5, 0.5) - *b).norm(), 1e-12);
  // The image corners map to each other.
  EXPECT_NEAR((cam.cx + 0.5) * 0.5 - 0.5, half.cx, 1e-12);
  EXPECT_THROW(cam.scaled(0, 1), Error);
}

TEST(Camera, InImageUsesPixelEdgesAtMinusHalfAndSizeMinusHalf) {
  Camera cam;
  cam.width = 10, cam.height = 5;
  EXPECT_TRUE(cam.inImage({-0.5, -0.5}));
  EXPECT_TRUE(cam.inImage({9.5, 4.5}));
  EXPECT_FALSE(cam.inImage({9.5001, 2}));
  EXPECT_FALSE(cam.inImage({2, -0.5001}));
  EXPECT_FALSE(cam.inImage({0, 0}, 1.0));
  EXPECT_TRUE(cam.inImage({0.5, 0.5}, 1.0));
}

TEST(Camera, ValidateNamesCameraAndField) {
  Camera cam;
  cam.name = "w3";
  cam.width = 640, cam.height = 480, cam.fx = 500, cam.fy = 500, cam.cx = 320, cam.cy = 240;
  EXPECT_NO_THROW(cam.validate());
  cam.fy = -1;
  try {
    cam.validate();
    FAIL() << "negative fy accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "w3");
    EXPECT_EQ(e.context().field, "fy");
    EXPECT_NE(std::string(e.what()).find("w3"), std::string::npos);
  }
  cam.fy = 500;
  cam.dist.k2 = std::nan("");
  try {
    cam.validate();
    FAIL() << "NaN k2 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "distortion.k2");
  }
}

// Brown-Conrady takes OpenCV's rational k4 k5 k6; a Kannala-Brandt lens has no k5 k6 and names
// the one it was given.
TEST(Camera, ValidateAcceptsRationalBrownAndNamesKannalaBrandtsK5) {
  Camera cam;
  cam.name = "w4";
  cam.width = 640, cam.height = 480, cam.fx = 500, cam.fy = 500, cam.cx = 320, cam.cy = 240;
  cam.dist = {0.1, 0.01, 0, 0, 0.001, 0.2, 0.02, 0.002};
  EXPECT_NO_THROW(cam.validate());
  EXPECT_TRUE(cam.dist.isRational());
  cam.dist = Distortion::kannalaBrandt(0.01, 0.0, 0.0, 0.001);
  EXPECT_NO_THROW(cam.validate());
  EXPECT_FALSE(cam.dist.isRational());
  for (const char* term : {"k5", "k6"}) {
    Camera bad = cam;
    (std::string(term) == "k5" ? bad.dist.k5 : bad.dist.k6) = 0.01;
    try {
      bad.validate();
      FAIL() << "kannala-brandt with " << term << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().camera, "w4");
      EXPECT_EQ(e.context().field, std::string("distortion.") + term);
      EXPECT_NE(e.message().find(term), std::string::npos) << e.message();
    }
  }
}

TEST(Camera, InverseOptionsValidateNamesTheField) {
  InverseOptions o;
  EXPECT_NO_THROW(o.validate());
  o.max_iterations = 0;
  try {
    o.validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "max_iterations");
  }
  o = {};
  o.tolerance = -1;
  try {
    o.validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "tolerance");
  }
  EXPECT_STREQ(toString(InverseStatus::kNotInvertible), "not invertible");
  EXPECT_STREQ(toString(InverseMethod::kFixedPoint), "fixed-point");
}

}  // namespace
}  // namespace previz
