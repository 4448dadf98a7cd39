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
  int shared_frames = 0;          // frames where both see >= min_points of the board
  int consistent_frames = 0;      // of those, frames whose relative pose T_a_b agrees (robust mean)
  double spread_m = 0;            // median deviation of T_a_b's translation over them
  double spread_deg = 0;          // ... of its rotation
};

struct RigCalibResult {
  Rig rig;                                 // every camera, intrinsics and T_world_cam
  std::vector<CameraCalibReport> cameras;  // same order as rig.cameras
  std::map<int, Pose> T_world_board;       // per frame used
  std::vector<GraphEdge> spanning_tree;    // edges used to initialise
  bool world_from_floor = false;
  int residuals = 0, rejected = 0;
  double rms_px = 0;
  double sigma_px = 0;                     // noise estimate per pixel coordinate (scales covariances)
  bool covariance_ok = false;              // false: normal equations singular, covariances zero
  double solve_ms = 0;                     // whole calibrateRig call
  int ceres_iterations = 0;
};

// initial: every camera of the take with its intrinsics (T_world_cam ignored, role kept).
// Cameras of obs that are not in 'initial' are ignored. A view is a camera's detections in one
// frame with >= min_points points; its board pose comes from a robust PnP (homography RANSAC
// on undistorted points, IPPE). Frames seen by one camera only are left out (unless they are
// floor frames, or that camera's intrinsics are solved). Intrinsics solved for a camera: fx fy
// cx cy k1 k2 p1 p2 (skew and k3 held). Noise groups: after each solve every camera's floor
// points and its other points are weighted by their own robust noise estimate (the floor board
// is seen at grazing angles: its corners are 2-4 times noisier; unweighted, the world frame
// leaned on them as on the rest and its reported sigma was ~2.7 times too small on rendered
// captures). Covariances: Gauss–Newton normal equations of the kept (weighted) points with the
// boards marginalised, scaled by the noise estimate sigma_px^2; they hold given the intrinsics
// that were not solved.
// A take whose every frame is a floor frame (static witnesses, no board waved: one still frame
// or a few) goes the same way: each camera's robust PnP on the floor board, the graph through
// the board they all see, the bundle with the floor board fixed (tests/multicam/rig_calib_test.cpp
// FloorOnly*); a camera that does not see the board is named ("does not see the floor board").
// Throws Error naming the camera when a camera has no usable view, or shares no board view
// (directly or through others) with the rest; naming the field 'floor' when obs has floor frames
// but no camera sees the floor board in them; and naming the camera and the field when
// options.reference_camera or a name in estimate_intrinsics is not a camera.
RigCalibResult calibrateRig(const RigObservations& obs, const Rig& initial,
                            const RigCalibOptions& options = {});

// Re-survey after a camera was bumped: 'rig' is the current calibration; capture is a short new
// capture (any number of frames, no floor needed). Every other camera stays fixed; the board
// poses come from them (PnP, then refined with the cameras held); the camera starts from the
// robust mean of its per-frame poses; then the camera (and its intrinsics if listed in options)
// and the board poses are refined together with every other camera held, robust loss and outlier
// rounds as in calibrateRig. Only frames the camera shares with another camera are used.
// report.covariance is conditional on the held cameras: it leaves out their own calibration
// error. Throws Error naming the camera when it is not in the rig, has no usable view, or
// shares none with the others.
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
// 'flag_px' is flagged (bumped or wrong calibration). Robust to the camera being checked: in
// each frame the board pose is the one most cameras agree on (median residual < 3 flag_px; one
// candidate per camera's own PnP), refined on the agreeing views only; frames where fewer than
// two cameras agree are not used. Every view of the used frames is then measured against it;
// gross outliers (above max(3 flag_px, 5 robust sigma)) are counted, not put in the RMS.
struct RigCheckCamera {
  std::string camera;
  int views = 0, points = 0;              // points: residuals in rms_px
  int outliers = 0;                       // residuals above max(3 flag_px, 5 robust sigma), left out
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
