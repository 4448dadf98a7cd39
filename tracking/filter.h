#pragma once
// Temporal filter on SE(3): a constant-velocity Kalman filter per axis of position (world, m) and
// of rotation (world axes, rad, on the tangent space around the prediction: R = Exp(dw) R_pred),
// with manoeuvre adaptation so that smoothing at rest costs no lag on fast moves.
//
// Why this design: a fixed-gain smoother trades jitter against lag (an alpha-beta filter that
// lags under one frame on a sudden 1 m/s start removes only ~20 % of the noise). Here the
// process noise is small (strong smoothing while the prop rests or glides), and each axis whose
// innovation is improbable under the current covariance (|y| > gate_sigma sigma) has its
// covariance inflated by the innovation itself (P_pos += y^2, P_vel += (y/dt)^2), which makes the
// gain near 1 for that frame: the estimate jumps to the measurement and the velocity follows —
// an adaptive Kalman filter in the manner of Sage–Husa / innovation-based adaptive estimation.
// Measurement noise per axis comes from the pose covariance of the solve (floored).
//
// Parameters (FilterOptions): accel_sigma_mps2 / angular_accel_sigma_radps2 — the white
// acceleration noise of the constant-velocity model (spectral density = sigma^2 * 1 s); lower =
// smoother; gate_sigma — innovations beyond this many sigmas count as a manoeuvre;
// min_position_sigma_m / min_rotation_sigma_rad — floors of the measurement noise (corners are
// never better than ~0.05 px); max_gap_s — longer without a measurement resets the filter.
#include <Eigen/Core>

#include "core/pose.h"

namespace previz::tracking {

struct FilterOptions {
  double accel_sigma_mps2 = 0.005;
  double angular_accel_sigma_radps2 = 0.01;
  double gate_sigma = 4.0;
  double min_position_sigma_m = 0.0002;
  double min_rotation_sigma_rad = 0.0002;
  double max_gap_s = 0.25;
  void validate() const;  // throws Error naming the field
};

class PoseFilter {
 public:
  explicit PoseFilter(const FilterOptions& options = {});

  bool initialised() const { return initialised_; }
  void reset() { initialised_ = false; }
  // Pose extrapolated to time_s from the last update (meaningful only when initialised()).
  Pose predict(double time_s) const;
  // Feeds the measurement of time_s with its 6x6 covariance (rotation xyz, position xyz; see
  // solve.h). Returns the filtered pose at time_s.
  Pose update(double time_s, const Pose& measured, const Eigen::Matrix<double, 6, 6>& covariance);
  Eigen::Vector3d velocity() const { return vel_.tail<3>(); }          // m/s, world
  Eigen::Vector3d angularVelocity() const { return vel_.head<3>(); }  // rad/s, world axes
  // Axes (of 6: rotation xyz, position xyz) treated as a manoeuvre in the last update.
  int manoeuvreAxes() const { return manoeuvre_axes_; }

 private:
  FilterOptions options_;
  bool initialised_ = false;
  double time_s_ = 0;
  Pose T_ = Pose::Identity();
  Eigen::Matrix<double, 6, 1> vel_ = Eigen::Matrix<double, 6, 1>::Zero();
  // Per axis 2x2 covariance [p pv; pv v] stored as (p, pv, v).
  Eigen::Matrix<double, 6, 3> P_ = Eigen::Matrix<double, 6, 3>::Zero();
  int manoeuvre_axes_ = 0;
};

}  // namespace previz::tracking
