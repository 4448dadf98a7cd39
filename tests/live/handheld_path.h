#pragma once
// The tracker-alignment tests' camera move: handheld-ish around a board 'distance_m' in front of
// it (board upright at y = 0): sways +-0.35 m sideways, +-0.15 m in height and depth, pans and
// tilts as it keeps the board in view, rolls +-4 degrees. 'pace' speeds the whole move up.
#include <cmath>

#include <Eigen/Geometry>

#include "core/pose.h"

namespace previz::live::handheld {

inline Pose aroundBoard(double t, double distance_m, double pace = 1.0) {
  t *= pace;
  const Eigen::Vector3d eye(0.35 * std::sin(2 * M_PI * 0.13 * t),
                            -distance_m + 0.15 * std::sin(2 * M_PI * 0.07 * t + 1),
                            1.4 + 0.15 * std::sin(2 * M_PI * 0.21 * t));
  const Eigen::Vector3d target(0.1 * std::sin(2 * M_PI * 0.17 * t), 0, 1.2 + 0.08 * std::cos(2 * M_PI * 0.11 * t));
  Pose T = lookAt(eye, target);
  T.linear() = T.linear() * Eigen::AngleAxisd(0.07 * std::sin(2 * M_PI * 0.19 * t), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

}  // namespace previz::live::handheld
