// .chan rotation order and the y-up conversions (batch/chan.h), against explicit rotations.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <fstream>
#include <random>

#include "batch/chan.h"
#include "core/error.h"
#include "scratch.h"

namespace previz::batch {
namespace {

Eigen::Matrix3d axis(double deg, const Eigen::Vector3d& a) {
  return Eigen::AngleAxisd(deg * M_PI / 180, a).toRotationMatrix();
}

TEST(BatchChan, RotationOrderZXYAppliesZThenXThenY) {
  const Eigen::Vector3d r(20, -35, 70);  // rx, ry, rz
  const Eigen::Matrix3d expected =
      axis(r.y(), Eigen::Vector3d::UnitY()) * axis(r.x(), Eigen::Vector3d::UnitX()) * axis(r.z(), Eigen::Vector3d::UnitZ());
  EXPECT_LT((rotationZXYDeg(r) - expected).norm(), 1e-12);
  // A pure 90° about z reads back as rz = 90 only.
  const Eigen::Vector3d e = eulerZXYDeg(axis(90, Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(e.x(), 0, 1e-9);
  EXPECT_NEAR(e.y(), 0, 1e-9);
  EXPECT_NEAR(e.z(), 90, 1e-9);
}

TEST(BatchChan, EulerAnglesRoundTripForRandomRotationsAndGimbalLock) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Matrix3d R = Eigen::Quaterniond(Eigen::Vector4d(u(rng), u(rng), u(rng), u(rng)).normalized()).toRotationMatrix();
    EXPECT_LT((rotationZXYDeg(eulerZXYDeg(R)) - R).norm(), 1e-9) << "rotation " << i;
  }
  const Eigen::Matrix3d lock = rotationZXYDeg(Eigen::Vector3d(90, 30, 10));
  EXPECT_LT((rotationZXYDeg(eulerZXYDeg(lock)) - lock).norm(), 1e-9);
}

TEST(BatchChan, UnwrapKeepsASpinContinuous) {
  std::vector<std::pair<int, Pose>> poses;
  for (int f = 0; f < 40; ++f) {
    Pose T = Pose::Identity();
    T.linear() = axis(10.0 * f, Eigen::Vector3d::UnitY());  // 0 .. 390 degrees about y
    poses.push_back({f, T});
  }
  const std::vector<ChanKey> keys = chanKeys(poses);
  for (size_t i = 1; i < keys.size(); ++i)
    EXPECT_NEAR(keys[i].rotate_deg.y() - keys[i - 1].rotate_deg.y(), 10.0, 1e-6) << "frame " << i;
}

TEST(BatchChan, YUpWorldAndCameraAxesFollowNukeAndMaya) {
  // World z up becomes y up; world y (into the stage) becomes -z.
  EXPECT_LT((yUpFromZUp() * Eigen::Vector3d(0, 0, 1) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-15);
  EXPECT_LT((yUpFromZUp() * Eigen::Vector3d(0, 1, 0) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-15);
  EXPECT_NEAR(yUpFromZUp().determinant(), 1.0, 1e-15);
  // An OpenCV camera at (1, -4, 1.5) looking along world +y, level (image down = world -z).
  Pose T = Pose::Identity();
  T.linear().col(0) = Eigen::Vector3d(1, 0, 0);   // x right
  T.linear().col(1) = Eigen::Vector3d(0, 0, -1);  // y down
  T.linear().col(2) = Eigen::Vector3d(0, 1, 0);   // z forward
  T.translation() = Eigen::Vector3d(1, -4, 1.5);
  const Pose P = cameraPoseForPost(T);
  // The CG camera looks down its -z: that must be world +y, i.e. y-up -z.
  EXPECT_LT((P.linear() * Eigen::Vector3d(0, 0, -1) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-12);
  // Its +y (image up) is world up.
  EXPECT_LT((P.linear() * Eigen::Vector3d(0, 1, 0) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-12);
  EXPECT_LT((P.translation() - Eigen::Vector3d(1, 1.5, 4)).norm(), 1e-12);
  // Level camera looking down -z of the y-up world: all angles zero.
  EXPECT_LT(eulerZXYDeg(P.linear()).norm(), 1e-9);
  EXPECT_LT((cameraPoseFromPost(P).matrix() - T.matrix()).norm(), 1e-12);
}

TEST(BatchChan, FileRoundTripAndBadLinesNameTheLine) {
  const auto dir = test::scratchDir("batch", "chan");
  std::vector<ChanKey> keys(2);
  keys[0] = {1001, Eigen::Vector3d(1.25, -0.5, 3.0), Eigen::Vector3d(10, 20, -30)};
  keys[1] = {1002, Eigen::Vector3d(1.26, -0.5, 3.1), Eigen::Vector3d(10.5, 20, -30)};
  writeChan(dir / "a.chan", keys);
  const std::vector<ChanKey> back = readChan(dir / "a.chan");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[1].frame, 1002);
  EXPECT_LT((back[1].translate - keys[1].translate).norm(), 1e-12);
  EXPECT_LT((back[1].rotate_deg - keys[1].rotate_deg).norm(), 1e-12);
  { std::ofstream(dir / "bad.chan") << "1 0 0 0 0 0 0\n2 0 0 0 0 0\n"; }
  try {
    readChan(dir / "bad.chan");
    FAIL() << "a 6-number line was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("bad.chan"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace previz::batch
