#include "core/box_tag.h"

#include <cmath>

namespace previz {

Pose boxFaceTagPose(const Eigen::Vector3d& n, const Eigen::Vector3d& half) {
  const Eigen::Vector3d z = -n;
  const Eigen::Vector3d y = std::abs(n.z()) > 0.5 ? Eigen::Vector3d(0, -1, 0) : Eigen::Vector3d(0, 0, -1);
  const Eigen::Vector3d x = y.cross(z);
  Pose T = Pose::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = n.cwiseProduct(half);
  return T;
}

}  // namespace previz
