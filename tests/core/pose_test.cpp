// Pose helpers: lookAt axes, rvec/tvec against cv::Rodrigues, distances, JSON.
#include "core/pose.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>

#include "core/camera.h"
#include "core/error.h"
#include "core/io.h"
#include "core/pose_lines.h"
#include "scratch.h"

namespace previz {
namespace {

TEST(Pose, LookAtPutsTargetOnTheOpticalAxisAndUpAtTheTopOfTheImage) {
  const Eigen::Vector3d eye(3, -2, 1.6), target(0, 0, 1.0);
  const Pose T_world_cam = lookAt(eye, target);
  const Eigen::Matrix3d R = T_world_cam.linear();
  EXPECT_LE((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-15);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-15);
  const Pose T_cam_world = T_world_cam.inverse();
  // Target straight ahead.
  const Eigen::Vector3d t_cam = T_cam_world * target;
  EXPECT_NEAR(t_cam.x(), 0, 1e-12);
  EXPECT_NEAR(t_cam.y(), 0, 1e-12);
  EXPECT_NEAR(t_cam.z(), (target - eye).norm(), 1e-12);
  // A point above the target appears above the centre (smaller image y); camera x stays level.
  const Eigen::Vector3d above = T_cam_world * (target + Eigen::Vector3d(0, 0, 0.5));
  EXPECT_LT(above.y(), 0.0);
  EXPECT_NEAR(R.col(0).z(), 0.0, 1e-15);
  // Looking along +x with z up: image right is world -y.
  const Pose T2 = lookAt({0, 0, 1}, {5, 0, 1});
  EXPECT_LE((T2.linear().col(0) - Eigen::Vector3d(0, -1, 0)).norm(), 1e-15);
  EXPECT_LE((T2.linear().col(1) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-15);
}

TEST(Pose, LookAtStraightDownIsAValidRotationAndRejectsEyeOnTarget) {
  const Pose T = lookAt({0, 0, 5}, {0, 0, 0});
  EXPECT_NEAR(T.linear().determinant(), 1.0, 1e-12);
  EXPECT_LE((T.linear().col(2) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-15);
  EXPECT_THROW(lookAt({1, 1, 1}, {1, 1, 1}), Error);
}

TEST(Pose, RvecTvecMatchesCvRodriguesAndRoundTrips) {
  std::mt19937 rng(1);
  std::normal_distribution<double> g(0, 1);
  for (int i = 0; i < 100; ++i) {
    Eigen::Vector3d rvec(g(rng), g(rng), g(rng));
    rvec *= (i % 10 == 0 ? 3.1 : 1.0) / std::max(1.0, rvec.norm());  // angles up to ~pi
    const Eigen::Vector3d tvec(g(rng), g(rng), g(rng));
    const Pose T = poseFromRvecTvec(rvec, tvec);
    cv::Mat R_cv;
    cv::Rodrigues(cv::Vec3d(rvec.x(), rvec.y(), rvec.z()), R_cv);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(T.linear()(r, c), R_cv.at<double>(r, c), 1e-14);
    Eigen::Vector3d rv2, tv2;
    poseToRvecTvec(T, rv2, tv2);
    EXPECT_LE((rv2 - rvec).norm(), 1e-12);
    EXPECT_EQ(tv2, tvec);
  }
  Eigen::Vector3d rv, tv;
  poseToRvecTvec(Pose::Identity(), rv, tv);
  EXPECT_EQ(rv.norm(), 0.0);
}

TEST(Pose, DistancesAreTheRelativeAngleAndTranslationGap) {
  const Pose a = poseFromRvecTvec({0, 0, 0.3}, {1, 2, 3});
  const Pose b = poseFromRvecTvec({0, 0, 0.3 + 1e-7}, {1, 2, 3.5});
  EXPECT_NEAR(rotationDistance(a, b), 1e-7, 1e-15);  // accurate for tiny angles
  EXPECT_NEAR(translationDistance(a, b), 0.5, 1e-15);
  const Pose c = poseFromRvecTvec({0, 3.0, 0}, {0, 0, 0});
  EXPECT_NEAR(rotationDistance(Pose::Identity(), c), 3.0, 1e-12);
}

TEST(Pose, JsonRoundTripIsBitExact) {
  const Pose T = lookAt({1.234567890123, -2.5, 1.75}, {0.1, 0.2, 0.9});
  const nlohmann::json j = nlohmann::json::parse(poseToJson(T).dump());
  const Pose U = poseFromJson(j);
  EXPECT_EQ(U.matrix(), T.matrix());
  EXPECT_EQ(j.at("R").size(), 3u);
  EXPECT_EQ(j.at("t").size(), 3u);
}

TEST(Pose, JsonErrorsNameTheField) {
  auto field_of = [](const nlohmann::json& j) {
    try {
      poseFromJson(j, "T_world_cam");
    } catch (const Error& e) {
      return e.context().field;
    }
    return std::string("<no error>");
  };
  nlohmann::json good = poseToJson(Pose::Identity());
  nlohmann::json j = good;
  j.erase("t");
  EXPECT_EQ(field_of(j), "T_world_cam.t");
  j = good;
  j["R"][1][2] = "x";
  EXPECT_EQ(field_of(j), "T_world_cam.R[1][2]");
  j = good;
  j["R"] = {{2, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // not a rotation
  EXPECT_EQ(field_of(j), "T_world_cam.R");
  j = good;
  j["R"] = {{-1, 0, 0}, {0, 1, 0}, {0, 0, 1}};  // a reflection
  EXPECT_EQ(field_of(j), "T_world_cam.R");
  EXPECT_EQ(field_of(nlohmann::json::array()), "T_world_cam");
}

TEST(PoseLines, TrackedLinesGivePosesLostAndBadFramesNone) {
  const auto dir = test::scratchDir("core", "pose_lines");
  const Pose T = lookAt(Eigen::Vector3d(1, 2, 3), Eigen::Vector3d::Zero());
  const std::string lines = nlohmann::json({{"frame", 4}, {"T_world_cam", poseToJson(T)}}).dump() + "\n  \n" +
                            nlohmann::json({{"frame", 5}, {"state", "tracked"}, {"T_world_cam", poseToJson(T)}}).dump() +
                            "\n" + nlohmann::json({{"frame", 6}, {"state", "lost"}, {"reason", "no tag"}}).dump() + "\n" +
                            nlohmann::json({{"frame", 7}, {"state", "bad frame"}}).dump() + "\n";
  writeFileAtomic(dir / "poses.jsonl", lines);
  std::map<int, std::string> unposed;
  const auto poses = readPoseLines(dir / "poses.jsonl", "T_world_cam", &unposed);
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_LT(translationDistance(poses.at(4), T), 1e-15);
  EXPECT_LT(rotationDistance(poses.at(5), T), 1e-12);
  ASSERT_EQ(unposed.size(), 2u);
  EXPECT_EQ(unposed.at(6), "no tag");
  EXPECT_EQ(unposed.at(7), "state \"bad frame\"");
  // A line without state must have the pose; a broken line is named.
  for (const std::string& bad : {std::string("{\"frame\": 1}"), std::string("{\"frame\": 1, \"T_world_cam\": 3}"),
                                 std::string("{\"frame\": \"x\"}"), std::string("{\"frame\": 1, ")}) {
    writeFileAtomic(dir / "bad.jsonl", lines + bad + "\n");
    try {
      readPoseLines(dir / "bad.jsonl");
      ADD_FAILURE() << "no error for " << bad;
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, "line 6") << e.what();
      EXPECT_NE(e.context().file.find("bad.jsonl"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace previz
