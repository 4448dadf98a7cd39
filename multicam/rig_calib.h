#pragma once
// Joint calibration of every camera of a stage in one world frame: camera graph from board
// co-observations, relative poses on a spanning tree of the most reliable edges, board poses by
// PnP, then a Ceres bundle adjustment over camera extrinsics and board poses (optionally
// intrinsics) with a robust loss and outlier rejection. The gauge is fixed by the floor board
// (world frame: origin at the floor board's origin, z up, metres); without floor frames by the
// reference camera.
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/rig.h"
#include "multicam/observations.h"

namespace previz::multicam {

struct RigCalibOptions {
  // Cameras whose intrinsics are refined in the solve ("*" = all). Others keep the intrinsics
  // they came with (calib results, or a lens-table entry for the main camera).
  std::vector<std::string> estimate_intrinsics;
  double huber_px = 1.0;          // robust loss scale
  double outlier_px = 0;          // residual above which a point is rejected; 0 = automatic
                                  // (max(1 px, 5 x the robust sigma of all residuals))
  int outlier_rounds = 3;
  int min_points = 6;             // a view with fewer points is not used
  std::string reference_camera;   // gauge without floor frames (default: the first camera)
  int threads = 0;
  void validate() const;          // throws Error naming the field
};

struct CameraCalibReport {
  std::string camera;
  int views = 0;                  // frames used
  int points = 0;                 // residuals kept
  int rejected = 0;               // outliers dropped
  double rms_px = 0;              // over kept residuals
  double sigma_position_m = 0;    // 1-sigma of the camera centre (largest axis), world frame
  double sigma_rotation_deg = 0;  // 1-sigma of the orientation (largest axis)
  // Covariance of the camera pose in the world frame: [rotation (rad, world axes);
  // position (m)], 6 x 6.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

struct GraphEdge {
  std::string a, b;
  int shared_frames = 0;
};

struct RigCalibResult {
  Rig rig;                                 // every camera, intrinsics and T_world_cam
  std::vector<CameraCalibReport> cameras;  // same order as rig.cameras
  std::map<int, Pose> T_world_board;       // per frame used
  std::vector<GraphEdge> spanning_tree;    // edges used to initialise
  bool world_from_floor = false;
  int residuals = 0, rejected = 0;
  double rms_px = 0;
  double solve_ms = 0;                     // whole calibrateRig call
  int ceres_iterations = 0;
};

// initial: every camera of the take with its intrinsics (T_world_cam ignored, role kept).
// Throws Error naming the camera when a camera has no usable view, or shares no board view
// (directly or through others) with the rest; and when obs has no floor frames and
// options.reference_camera is not a camera.
RigCalibResult calibrateRig(const RigObservations& obs, const Rig& initial,
                            const RigCalibOptions& options = {});

// Re-survey after a camera was bumped: 'rig' is the current calibration; capture is a short new
// capture (any number of frames, no floor needed). Every other camera stays fixed; the board
// poses come from them; only 'camera' (and its intrinsics if listed in options) is solved.
struct ResurveyResult {
  RigCamera before, after;
  CameraCalibReport report;
  double moved_m = 0, rotated_deg = 0;     // |after - before|
  Rig rig;                                 // 'rig' with the camera replaced
};
ResurveyResult resurveyCamera(const Rig& rig, const std::string& camera,
                              const RigObservations& capture,
                              const RigCalibOptions& options = {});

// Reprojection check of a calibrated rig on a new capture: board poses solved with every
// camera fixed; per camera RMS and how many views it had. A camera whose RMS is more than
// 'flag_px' is flagged (bumped or wrong calibration).
struct RigCheckCamera {
  std::string camera;
  int views = 0, points = 0;
  double rms_px = 0, median_px = 0;
  bool flagged = false;
  std::string reason;
};
struct RigCheckResult {
  std::vector<RigCheckCamera> cameras;
  bool ok = true;
};
RigCheckResult checkRig(const Rig& rig, const RigObservations& capture, double flag_px = 1.0);

}  // namespace previz::multicam
