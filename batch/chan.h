#pragma once
// Animation for post: Nuke/Maya `.chan` files (one line per frame: frame tx ty tz rx ry rz,
// metres and degrees) in a y-up world with rotation order ZXY (Nuke's default for cameras and
// Axis nodes: rotate about Z first, then X, then Y, i.e. R = Ry · Rx · Rz), and the conversions
// from previz's z-up world and OpenCV camera axes (docs/conventions.md, docs/formats.md "Batch").
#include <filesystem>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"

namespace previz::batch {

// (x, y, z)_yup = (x, z, -y) of previz's z-up world: a proper rotation (-90° about x).
Eigen::Matrix3d yUpFromZUp();
// A camera for Nuke/Maya (x right, y up, looking down -z) from previz's T_world_cam (OpenCV
// camera axes, z-up world): T_yup_cgcam = A · T_world_cam · diag(1, -1, -1).
Pose cameraPoseForPost(const Pose& T_world_cam);
// An object (prop) for post: T_yup_obj = A · T_world_obj; the object's own axes are kept.
Pose objectPoseForPost(const Pose& T_world_obj);
// Inverse of cameraPoseForPost.
Pose cameraPoseFromPost(const Pose& T_yup_cgcam);

// R = Ry(ry) · Rx(rx) · Rz(rz), angles in degrees (rotation order ZXY).
Eigen::Matrix3d rotationZXYDeg(const Eigen::Vector3d& r_deg);
// The angles (degrees) of R in order ZXY, rx in [-90, 90]; 'near' (if given) picks among the
// equivalent angle sets by adding multiples of 360° so a sequence does not jump.
Eigen::Vector3d eulerZXYDeg(const Eigen::Matrix3d& R, const Eigen::Vector3d* near = nullptr);

struct ChanKey {
  int frame = 0;
  Eigen::Vector3d translate = Eigen::Vector3d::Zero();  // metres
  Eigen::Vector3d rotate_deg = Eigen::Vector3d::Zero();
  Pose pose() const;  // translate + rotationZXYDeg(rotate_deg)
};
// Keys of a pose sequence (frame order kept), angles unwrapped frame to frame.
std::vector<ChanKey> chanKeys(const std::vector<std::pair<int, Pose>>& poses);

// Writes atomically ("%d %.9g ..." per line, no header: Nuke and Maya read bare numbers).
void writeChan(const std::filesystem::path& path, const std::vector<ChanKey>& keys);
// Reads 7 numbers per line (blank lines and '#' lines skipped); errors name the file and line.
std::vector<ChanKey> readChan(const std::filesystem::path& path);

}  // namespace previz::batch
