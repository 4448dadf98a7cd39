#pragma once
// Internal to previz_multicam: board views of a rig capture with a robust single-view pose,
// and the robust pose average the camera graph and the world frame are initialised with.
// Poses follow docs/conventions.md (T_a_b maps b -> a); pixels are OpenCV's.
#include <map>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/pose.h"
#include "core/rig.h"
#include "multicam/observations.h"

namespace previz::multicam::detail {

// One camera's board view in one frame (points with an id on that frame's board, finite,
// without duplicates) and its pose from a robust PnP.
struct View {
  int camera = -1;   // index into the rig
  int frame = -1;
  std::vector<int> ids;
  std::vector<Eigen::Vector3d> p_board;
  std::vector<Eigen::Vector2d> px;
  bool posed = false;                    // PnP succeeded
  Pose T_cam_board = Pose::Identity();
  int inliers = 0;                       // points within 3 px of the PnP pose
};

// Per rig camera (rig order): frame -> view, for views with at least min_points points. Cameras
// of obs that are not in the rig are ignored; a rig camera absent from obs has no views.
// Throws Error naming camera and frame for a point id that is not on the frame's board, and
// naming the camera when its detections' image size differs from its intrinsics.
std::vector<std::map<int, View>> collectViews(const RigObservations& obs, const Rig& rig,
                                              int min_points, int threads);

// Pose of the board in the camera from one view: homography RANSAC on undistorted points
// (throws out gross outliers), IPPE on the inliers, iterative refinement. false when the view
// is degenerate (collinear points) or no pose explains enough of it.
bool robustViewPose(const Camera& camera, View& view, int min_points);

// Robust mean of poses that should agree (one relative pose seen in many frames): the medoid
// under d = |dt| + length_m * angle, the samples within max(3 x median d, floor_m) of it, their
// mean (translation mean, sign-aligned quaternion mean). Spreads are medians over the inliers.
struct PoseMean {
  Pose mean = Pose::Identity();
  int samples = 0, inliers = 0;
  double spread_m = 0, spread_rad = 0;
};
PoseMean robustMeanPose(const std::vector<Pose>& samples, double length_m = 1.0,
                        double floor_m = 0.01);

// Residual norms (px) of a view's points for a board pose in the camera.
std::vector<double> viewResiduals(const Camera& camera, const View& view, const Pose& T_cam_board);

}  // namespace previz::multicam::detail
