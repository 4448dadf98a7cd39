#include "core/pose.h"

#include <cmath>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/error.h"

namespace previz {

Pose lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d forward = target - eye;
  if (!(forward.norm() > 0.0) || !forward.allFinite())
    throw Error("lookAt: eye and target must be distinct finite points", fieldContext("target"));
  if (!(up.norm() > 0.0) || !up.allFinite())
    throw Error("lookAt: up must be a finite non-zero vector", fieldContext("up"));
  const Eigen::Vector3d z = forward.normalized();
  Eigen::Vector3d x = z.cross(up);
  if (x.norm() < 1e-9 * up.norm()) {
    // Looking along 'up' (an overhead camera): any roll is as good as another; take the world
    // axis least aligned with the view so the result is deterministic.
    Eigen::Index axis;
    z.cwiseAbs().minCoeff(&axis);
    x = z.cross(Eigen::Vector3d::Unit(axis));
  }
  x.normalize();
  // OpenCV camera: x right, y down, z forward; y = z × x points away from 'up'.
  const Eigen::Vector3d y = z.cross(x);
  Pose T = Pose::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = eye;
  return T;
}

Pose poseFromRvecTvec(const Eigen::Vector3d& rvec, const Eigen::Vector3d& tvec) {
  Pose T = Pose::Identity();
  const double angle = rvec.norm();
  if (angle > 0.0) T.linear() = Eigen::AngleAxisd(angle, rvec / angle).toRotationMatrix();
  T.translation() = tvec;
  return T;
}

void poseToRvecTvec(const Pose& T, Eigen::Vector3d& rvec, Eigen::Vector3d& tvec) {
  const Eigen::AngleAxisd aa(T.rotation());
  rvec = aa.axis() * aa.angle();
  tvec = T.translation();
}

double rotationDistance(const Pose& a, const Pose& b) {
  // Eigen takes the angle from the quaternion (2 atan2(|v|, |w|)): accurate near 0 and pi,
  // unlike acos((trace - 1) / 2).
  return Eigen::AngleAxisd(a.rotation().transpose() * b.rotation()).angle();
}

double translationDistance(const Pose& a, const Pose& b) {
  return (a.translation() - b.translation()).norm();
}

nlohmann::json poseToJson(const Pose& T) {
  nlohmann::json R = nlohmann::json::array();
  for (int r = 0; r < 3; ++r)
    R.push_back({T.linear()(r, 0), T.linear()(r, 1), T.linear()(r, 2)});
  return {{"R", R}, {"t", {T.translation().x(), T.translation().y(), T.translation().z()}}};
}

Pose poseFromJson(const nlohmann::json& j, const std::string& what) {
  auto fail = [&](const std::string& field, const std::string& expected) {
    throw Error(what + ": expected " + expected, fieldContext(field));
  };
  if (!j.is_object()) fail(what, "an object {\"R\": [[3],[3],[3]], \"t\": [3]}");
  const std::string fR = what + ".R", ft = what + ".t";
  if (!j.contains("R")) fail(fR, "a 3x3 rotation (array of 3 rows of 3 numbers), field missing");
  if (!j.contains("t")) fail(ft, "a translation (array of 3 numbers, metres), field missing");
  const auto& jR = j.at("R");
  const auto& jt = j.at("t");
  if (!jR.is_array() || jR.size() != 3) fail(fR, "an array of 3 rows of 3 numbers");
  Eigen::Matrix3d R;
  for (int r = 0; r < 3; ++r) {
    if (!jR[r].is_array() || jR[r].size() != 3) fail(fR, "an array of 3 rows of 3 numbers");
    for (int c = 0; c < 3; ++c) {
      if (!jR[r][c].is_number())
        fail(fR + "[" + std::to_string(r) + "][" + std::to_string(c) + "]", "a number");
      R(r, c) = jR[r][c].get<double>();
    }
  }
  if (!jt.is_array() || jt.size() != 3) fail(ft, "an array of 3 numbers (metres)");
  Eigen::Vector3d t;
  for (int i = 0; i < 3; ++i) {
    if (!jt[i].is_number()) fail(ft + "[" + std::to_string(i) + "]", "a number");
    t[i] = jt[i].get<double>();
  }
  if (!R.allFinite() || !t.allFinite()) fail(what, "finite numbers");
  // Values written by poseToJson come back bit-exact (JSON doubles round-trip); the tolerance
  // admits hand-written or 9-digit rotations but not a matrix that is not a rotation at all.
  const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (err > 1e-6 || R.determinant() <= 0.0) {
    std::ostringstream s;
    s << "a proper rotation (R^T R = I within 1e-6, det = +1); got |R^T R - I| = " << err
      << ", det = " << R.determinant();
    fail(fR, s.str());
  }
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

}  // namespace previz
