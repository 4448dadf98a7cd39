#pragma once
// Rigid pose from AprilTag corners seen by calibrated cameras: per-tag IPPE (OpenCV's
// SOLVEPNP_IPPE_SQUARE, both solutions) to initialise, every candidate scored against every
// corner of every view (this is what resolves the two-fold ambiguity of a small tag: the wrong
// flip of one view's tag does not explain the other views), then one Ceres solve over all corners
// with a robust loss, one round of outlier removal, and the pose covariance.
// Poses T_a_b map b -> a; pixels: docs/conventions.md.
#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"
#include "core/rig.h"
#include "tracking/props.h"

namespace previz::tracking {

// One tag seen by one camera.
struct TagObservation {
  int camera = 0;                          // index into the cameras passed to the solver
  int tag = 0;                             // index into PropDef::tags
  std::array<Eigen::Vector2d, 4> px;       // detected corners (distorted pixels), p[0..3]
  std::array<Eigen::Vector2d, 4> ideal;    // the same, undistorted: ideal normalized (x/z, y/z)
  std::array<bool, 4> valid{{true, true, true, true}};  // false where undistortion failed
};

// Undistorts the four corners with the camera model (Camera::undistort, Newton); corners whose
// inverse does not converge are marked invalid.
TagObservation makeTagObservation(const Camera& camera, int camera_index, int tag,
                                  const std::array<Eigen::Vector2d, 4>& corners_px);

struct SolveOptions {
  double huber_px = 1.0;        // robust loss scale (pixels of the camera's mean focal length)
  double outlier_px = 3.0;      // corners farther than this after the first solve are dropped
  double min_sigma_px = 0.05;   // floor of the corner noise estimate used for the covariance
  int max_iterations = 30;
  void validate() const;        // throws Error naming the field
};

struct PoseEstimate {
  bool ok = false;
  std::string failure;          // why not, when !ok
  Pose T = Pose::Identity();    // T_world_prop (solvePropPose) or T_world_cam (solveCameraPose)
  // 6x6 covariance, order rotation x y z (rad, world axes, left perturbation T = Exp(w) T) then
  // position x y z (m, world) of the prop centre / camera centre.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  double sigma_position_m = 0;  // sqrt of the largest eigenvalue of the position block (1 sigma)
  double sigma_rotation_rad = 0;
  double rms_px = 0;            // of the inlier corners
  double sigma_px = 0;          // corner noise estimate used for the covariance
  int tags = 0;                 // tag observations used
  int corners = 0;              // corners given
  int inliers = 0;              // corners kept
  std::vector<int> cameras;     // camera indices with at least one inlier corner, ascending
  // Score of the best initial candidate whose rotation differs from the chosen one by more than
  // 10 degrees, over the chosen one's (robust squared reprojection sums); +inf when none. Near 1:
  // the views could not tell the two IPPE flips apart.
  double ambiguity_ratio = 0;
  int iterations = 0;
};

// Prop pose from fixed cameras (rig poses). 'prior' (e.g. last frame's pose) joins the initial
// candidates when given.
PoseEstimate solvePropPose(const std::vector<RigCamera>& cameras, const PropDef& prop,
                           const std::vector<TagObservation>& observations, const SolveOptions& options,
                           const Pose* prior = nullptr);

// One camera's pose T_world_cam from tags fixed in the world: 'tags' is a prop whose
// T_world_prop is set (studio tags). Observations' camera index is ignored.
PoseEstimate solveCameraPose(const Camera& camera, const PropDef& tags,
                             const std::vector<TagObservation>& observations, const SolveOptions& options,
                             const Pose* prior = nullptr);

}  // namespace previz::tracking
