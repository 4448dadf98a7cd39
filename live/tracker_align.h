#pragma once
// Aligning the camera tracker to the lens (`previz tracker align`): a tracker reports the pose
// of its own mount, not of the lens's entrance pupil, and its samples arrive some time after
// their instant. From a take of a calibration board filmed by the main camera while the
// tracker streams, solve jointly (Ceres, Levenberg–Marquardt, Huber loss on pixels):
//   T_tracker_cam   the lens in the tracked body's frame (6 DoF; hand–eye, AX = XB)
//   T_stage_board   the (static) board in the tracker's stage frame (6 DoF)
//   delay_s         tracker arrival - sample instant (matching by arrival, live/tracker.h)
// minimising the board corners' reprojection error in the main camera, whose intrinsics are
// known (calibrated): T_cam_board(f) = T_tracker_cam⁻¹ · T_stage_tracker(t_f + delay)⁻¹ ·
// T_stage_board, with T_stage_tracker interpolated between the samples as the matcher does
// (translation linear, rotation slerp) at arrival time t_f + delay. The delay is found first on
// a grid (delay_search_s, 2 ms steps, the offsets solved at each), then refined with the rest.
// 1σ from the covariance of the solution (Ceres Covariance) scaled by the residuals' variance.
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/camera.h"
#include "core/pose.h"

namespace previz::live {

// The board's corners seen in one video frame.
struct BoardView {
  int frame = 0;
  double time_s = 0;                          // the frame's instant on the take's clock
  std::vector<Eigen::Vector3d> board_points;  // board frame, metres
  std::vector<Eigen::Vector2d> pixels;        // OpenCV pixel convention (docs/conventions.md)
};

// A tracker sample: its arrival on the receiver's clock (the same clock as the frames' instants)
// and the tracked body's pose in the stage frame.
struct AlignSample {
  double arrival_s = 0;
  Pose T_stage_tracker = Pose::Identity();
};

struct TrackerAlignOptions {
  double delay_search_s = 0.25;  // the delay is looked for in [-search, +search]
  double delay_step_s = 0.002;
  double huber_px = 2.0;
  int max_iterations = 200;
  int min_points = 6;            // a view with fewer corners is not used
  // The tracker samples at a fixed rate, so its arrival jitter (network, scheduling) is noise on
  // the sample instants, which the solve would take as pose: fit arrival ≈ a + b · k to the
  // samples (k = the sample's number at the median period, gaps from losses counted) and use the
  // fitted instants. At 1 m/s, ±2 ms of jitter is ±2 mm of pose on every sample.
  bool regular_rate = true;
  void validate() const;         // throws Error naming the field
};

struct TrackerAlignResult {
  Pose T_tracker_cam = Pose::Identity();
  Pose T_stage_board = Pose::Identity();
  double delay_s = 0;
  // 1σ: position of the lens in the tracker frame (worst axis, m), rotation (worst axis, rad),
  // delay (s).
  double sigma_position_m = 0, sigma_rotation_rad = 0, sigma_delay_s = 0;
  bool covariance_ok = false;
  double rms_px = 0;
  int views = 0, views_dropped = 0, points = 0, iterations = 0;
  double solve_ms = 0;
  std::vector<std::pair<double, double>> delay_grid;  // (delay, RMS px) of the grid search
  double arrival_jitter_ms = 0;   // RMS of arrivals about the fitted rate (regular_rate), 0 otherwise
  double sample_period_s = 0;     // the fitted period
  std::string fullReport() const;
  nlohmann::json toJson() const;
};

// Throws Error when fewer than 3 views have tracker samples around them or the solve fails.
TrackerAlignResult alignTracker(const std::vector<BoardView>& views, const Camera& camera,
                                const std::vector<AlignSample>& samples, const TrackerAlignOptions& options);

}  // namespace previz::live
