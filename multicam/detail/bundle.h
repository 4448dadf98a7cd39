#pragma once
// Internal to previz_multicam: the bundle adjustment calibrateRig, resurveyCamera and checkRig
// share. Unknowns: camera poses T_world_cam (optionally intrinsics) and board poses
// T_world_board; each may be held fixed (gauge, re-survey, check). Ceres stays in the .cpp.
// Poses follow docs/conventions.md (T_a_b maps b -> a).
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/pose.h"

namespace previz::multicam::detail {

struct BundleCamera {
  Camera camera;                       // intrinsics (updated when some are free)
  Pose T_world_cam = Pose::Identity();
  bool pose_fixed = false;
  // Intrinsic indices (calib/detail/projection.h IntrinsicIndex) solved; empty = all held.
  std::vector<int> free_intrinsics;
};

struct BundleBoard {
  Pose T_world_board = Pose::Identity();
  bool fixed = false;
  // >= 0: the board shows a static scene seen at its own angle (the floor board in its floor
  // frames): its points form their own noise group per camera (BundleOptions::noise_groups).
  int static_scene = -1;
};

struct BundlePoint {
  int camera = -1;
  int board = -1;
  Eigen::Vector3d p_board = Eigen::Vector3d::Zero();
  Eigen::Vector2d px = Eigen::Vector2d::Zero();
  bool active = true;
  // Residual weight, set by solveBundle: sigma of all points / sigma of the point's noise group
  // (one camera's static-scene views, or its other views).
  double weight = 1.0;
};

struct BundleProblem {
  std::vector<BundleCamera> cameras;
  std::vector<BundleBoard> boards;
  std::vector<BundlePoint> points;
  // Every camera's centre is taken as rig_scale x T_world_cam.translation() (a rig imported in
  // other units, or with none: multicam/floor_world.h); solved when rig_scale_free. Anything but
  // 1 and held needs every camera's pose and intrinsics held (the scale would trade against them).
  double rig_scale = 1.0;
  bool rig_scale_free = false;
};

struct BundleOptions {
  double huber_px = 1.0;
  double outlier_px = 0;   // 0: max(1 px, 5 x robust sigma) per round, on weighted residuals
  int outlier_rounds = 3;
  // Weight each camera's static-scene points (the floor board, seen at grazing angles: their
  // detections are 2-4 times noisier) and its other points by their own noise, estimated from
  // the residuals after each solve (variance components; groups under 30 points keep weight 1).
  bool noise_groups = true;
  int min_points = 6;      // a (camera, board) view left with fewer active points is dropped
  int threads = 1;
  int max_iterations = 100;
};

struct BundleStats {
  int iterations = 0;
  int rejection_rounds = 0;
  int rejected = 0;             // points deactivated by the solve (outliers, dropped views)
  std::string message;          // Ceres' termination message of the last solve
};

// The free intrinsics when a camera's intrinsics are estimated: focal lengths, principal point,
// and Brown-Conrady's k1 k2 p1 p2 (skew and k3 stay as given: a rig capture rarely pins k3 down)
// or Kannala-Brandt's k1 k2 (k3 k4 as given).
std::vector<int> defaultFreeIntrinsics(LensModel model);

// Solves in place: the camera and board poses (and free intrinsics) move, outlier points get
// active = false. Points whose camera or board is absent from the problem are ignored. Points
// behind their camera at the start are deactivated. Throws Error when Ceres fails.
BundleStats solveBundle(BundleProblem& problem, const BundleOptions& options);

// Observed minus predicted pixel (finite; a point behind the camera gives a huge residual).
Eigen::Vector2d bundleResidual(const BundleProblem& problem, const BundlePoint& point);

// Noise estimate per pixel coordinate from the active points' weighted residuals:
// sqrt(sum (w r)^2 / (2 n - free params)).
double bundleSigmaPx(const BundleProblem& problem);

// Covariance of every camera's pose, [rotation (rad, world axes: R_world_cam perturbed as
// exp(d) R); camera centre (m, world)], from the Gauss–Newton normal equations of the active
// points (weighted) with the boards marginalised (Schur complement) and free intrinsics
// included. Zero for fixed cameras. ok = false when the system is singular. rig_scale_sigma,
// when given: the standard deviation of a free rig_scale (0 when it is held).
std::vector<Eigen::Matrix<double, 6, 6>> bundleCameraCovariances(const BundleProblem& problem,
                                                                 double sigma_px, bool* ok,
                                                                 double* rig_scale_sigma = nullptr);

}  // namespace previz::multicam::detail
