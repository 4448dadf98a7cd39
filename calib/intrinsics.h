#pragma once
// Intrinsic calibration of one camera from views of a planar board: OpenCV's calibrateCamera
// gives the starting point (cv::fisheye::calibrate for a Kannala–Brandt lens), then a Ceres bundle
// adjustment over the intrinsics (fx fy cx cy [skew] and the lens model's terms: k1 k2 p1 p2 k3 [k4
// k5 k6, the rational model], or k1 k2 k3 k4) and every board pose, with a robust loss, outlier rejection, parameter
// locks and a covariance that says how sure each parameter is. The result explains itself
// (IntrinsicsResult::fullReport()).
// Pixels: (0,0) = centre of the top-left pixel; board frame and poses: docs/conventions.md.
#include <array>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "calib/observations.h"
#include "core/board.h"
#include "core/camera.h"
#include "core/pose.h"

namespace previz::calib {

// Order of the intrinsic vector used by covariances and sigmas.
// The lens model decides which distortion terms are free: Brown–Conrady k1 k2 p1 p2 k3 (and its
// rational k4 k5 k6 under IntrinsicLocks::rational, else held), Kannala–Brandt k1 k2 k3 k4 (p1 p2
// k5 k6 held at 0).
constexpr int kIntrinsicCount = 13;
extern const std::array<const char*, kIntrinsicCount> kIntrinsicNames;  // fx fy cx cy skew k1 k2 p1 p2 k3 k4 k5 k6

// Parameters held at their initial value (from IntrinsicsOptions::initial_camera, else: aspect
// 1, principal point at the image centre ((w-1)/2, (h-1)/2), distortion 0).
struct IntrinsicLocks {
  bool fix_focal = false;            // fx and fy (needs initial_camera)
  bool fix_aspect = false;           // fy / fx held; fx still free
  bool fix_principal_point = false;  // cx, cy
  bool fix_skew = true;              // skew is estimated only when this is cleared
  bool fix_k1 = false, fix_k2 = false, fix_k3 = false, fix_k4 = false;
  bool fix_k5 = false, fix_k6 = false;  // the rational terms (with rational)
  bool fix_tangential = false;       // p1, p2
  // Brown–Conrady: also solve the rational terms k4 k5 k6 (OpenCV's CALIB_RATIONAL_MODEL; fix_k4..6
  // still hold single ones). Without it they are held (at 0 unless initial_camera has them).
  // Kannala–Brandt ignores it (its k4 is free unless fix_k4; it has no k5 k6).
  bool rational = false;

  // "fix_k3,fix_aspect": comma-separated names of the flags above, plus fix_distortion (all of
  // k1..k6 p1 p2), fix_radial (k1..k6), free_skew and rational. Throws Error naming the bad name.
  static IntrinsicLocks parse(const std::string& list);
  std::string toString() const;  // the set flags, comma-separated ("" when none)
  // Per intrinsic (kIntrinsicNames order): true when held. fy counts as held under fix_aspect
  // (it follows fx); the terms the lens model does not have are held (at 0).
  std::array<bool, kIntrinsicCount> heldMask(LensModel model) const;
};

enum class RobustLoss { kNone, kHuber, kCauchy };
const char* toString(RobustLoss loss);
RobustLoss robustLossFromString(const std::string& name);  // throws Error naming the value

struct IntrinsicsOptions {
  IntrinsicLocks locks;
  // The lens model solved for. initial_camera, when given, must have the same one.
  LensModel model = LensModel::kBrownConrady;
  RobustLoss loss = RobustLoss::kHuber;
  double loss_scale_px = 1.0;       // residual norm where the robust loss departs from squares
  bool reject_outliers = true;
  // A point is dropped when its residual norm exceeds outlier_sigma times the robust residual
  // scale (median norm / 1.1774, the Rayleigh median for isotropic Gaussian noise), then the
  // problem is re-solved; at most max_rejection_rounds times.
  double outlier_sigma = 5.0;
  int max_rejection_rounds = 3;
  int min_points_per_view = 6;      // views with fewer usable points are left out (reported)
  int min_views = 3;
  int max_iterations = 200;
  bool compute_covariance = true;
  // Also keep the joint covariance of the intrinsics and every board pose (needed by
  // validation.h's kMeanFrames uncertainty). Its size grows as (10 + 6 views)^2.
  bool joint_covariance = true;
  // Start from this camera (and use it for the held parameters) instead of image-size defaults.
  std::optional<Camera> initial_camera;
  // false: skip cv::calibrateCamera and start from initial_camera with solvePnP poses (used by
  // the frontal refinement, which already has a good estimate). Needs initial_camera.
  bool opencv_init = true;
  std::string camera_name = "camera";
  int threads = 1;                  // Ceres threads

  void validate() const;  // throws Error naming the field
};

// One input view as the solve saw it.
struct ViewResult {
  std::string source;
  bool used = false;              // false: left out (reason in dropped_reason)
  std::string dropped_reason;
  Pose T_cam_board = Pose::Identity();
  int points = 0;                 // points detected in the view
  int points_used = 0;            // after outlier rejection
  int points_rejected = 0;
  double rms_px = 0;              // over the used points
  double max_px = 0;              // largest residual over the used points
};

// Residual of one detected point at the final estimate.
struct PointResidual {
  int view = 0;                   // index into IntrinsicsResult::views
  int id = 0;                     // board point id
  Eigen::Vector2d px = Eigen::Vector2d::Zero();        // detected
  Eigen::Vector2d residual = Eigen::Vector2d::Zero();  // detected - projected, px
  bool rejected = false;          // dropped as an outlier
};

struct IntrinsicsResult {
  Camera camera;                  // the estimate
  Camera initial_camera;          // where the solve started (OpenCV's answer or initial_camera)
  double initial_rms_px = 0;      // OpenCV's RMS (or the RMS at initial_camera)
  cv::Size image_size;
  IntrinsicLocks locks;

  // Standard deviations in kIntrinsicNames order (0 for held parameters), from the covariance
  // scaled by the residual variance. covariance is kIntrinsicCount square in the same order.
  std::array<double, kIntrinsicCount> sigma{};
  Eigen::MatrixXd covariance;
  bool covariance_ok = false;
  std::string covariance_message;  // why it failed, when it did
  // Joint covariance of [intrinsics (kIntrinsicCount), then for each used view in order: angle-axis (3),
  // translation (3) of T_cam_board] when IntrinsicsOptions::joint_covariance.
  Eigen::MatrixXd joint_covariance;
  std::vector<int> joint_views;   // view index of each pose block of joint_covariance

  std::vector<ViewResult> views;  // one per input view, input order
  std::vector<PointResidual> residuals;
  int views_used = 0;
  int points_total = 0;           // points in the used views
  int points_used = 0;
  int points_rejected = 0;
  int rejection_rounds = 0;       // re-solves triggered by outliers
  int free_parameters = 0;        // free intrinsics + 6 per used view
  double rms_px = 0;              // RMS residual norm over the used points
  double rms_all_px = 0;          // ... including the rejected points
  double residual_sigma_px = 0;   // per-coordinate noise estimate sqrt(SSR / (2N - P))

  int iterations = 0;             // Ceres iterations, all rounds
  std::string termination;        // Ceres' last termination message
  double solve_ms = 0;            // whole call

  std::string briefReport() const;  // one line
  std::string fullReport() const;   // parameters with sigma, views, rejections (like Ceres')
};

// Calibrates from the views that found a board (views not found or marked rejected are listed
// in the result, not used). Throws Error when fewer than min_views views are usable or the image
// sizes disagree (naming the view).
IntrinsicsResult calibrateIntrinsics(const std::vector<ViewObservations>& views,
                                     const BoardSpec& board, const IntrinsicsOptions& options = {});

// Board pose of one view for a known camera: solvePnP (IPPE, planar), then with refine a
// least-squares polish through previz's model (OpenCV's PnP ignores skew). nullopt when there
// are too few points or PnP fails.
std::optional<Pose> estimateBoardPose(const Camera& camera, const ViewObservations& view,
                                      const BoardSpec& board, bool refine = true);

}  // namespace previz::calib
