#pragma once
// Rigid poses. A pose T_a_b maps points from frame b to frame a: p_a = T_a_b * p_b.
// World: z up, floor at z = 0, metres. Camera: OpenCV (x right, y down, z forward).
#include <Eigen/Geometry>
#include <nlohmann/json_fwd.hpp>

namespace previz {

using Pose = Eigen::Isometry3d;

// Camera pose looking from eye at target, with world 'up' projecting to the image's -y.
// Returns T_world_cam (OpenCV camera axes).
Pose lookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
            const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

// OpenCV rvec/tvec (T_cam_obj as solvePnP returns it) <-> Pose.
Pose poseFromRvecTvec(const Eigen::Vector3d& rvec, const Eigen::Vector3d& tvec);
void poseToRvecTvec(const Pose& T, Eigen::Vector3d& rvec, Eigen::Vector3d& tvec);

// Angle of the relative rotation between two poses, radians.
double rotationDistance(const Pose& a, const Pose& b);
// Distance between the translations, metres.
double translationDistance(const Pose& a, const Pose& b);

// JSON: {"R": [[...],[...],[...]], "t": [x, y, z]} (row-major rotation, metres).
// fromJson throws Error naming the field on malformed input; 'what' is used in messages.
nlohmann::json poseToJson(const Pose& T);
Pose poseFromJson(const nlohmann::json& j, const std::string& what = "pose");

}  // namespace previz
