#pragma once
// Temporal filter on SE(3): constant-velocity Kalman filters per axis of position (world, m) and
// of rotation (world axes, rad, on the tangent space around the prediction: R = Exp(dw) R_pred),
// two motion models mixed as an IMM, and manoeuvre adaptation, so that smoothing at rest costs no
// lag on fast moves and turns.
//
// Why this design: a fixed-gain smoother trades jitter against lag (an alpha-beta filter that
// lags under one frame on a sudden 1 m/s start removes only ~20 % of the noise). Here the
// process noise is small (strong smoothing while the prop rests, glides or turns steadily), and:
// - Two constant-velocity models, mixed by their measurement likelihoods (interacting multiple
//   model, Blom & Bar-Shalom 1988; one mode probability for the body, Markov switching with mean
//   dwell model_dwell_s): "straight" — the prop origin moves at a constant world velocity while
//   the body turns at a constant angular velocity (a prop carried across the set while it turns)
//   — and "screw" — a constant twist: the origin's velocity turns with the body,
//   p' = p + J(w dt) v dt, v' = Exp(w dt) v (a prop turned in the hand about any axis: the axis
//   rarely passes through the prop origin, and the origin then runs on a circle, which the
//   straight model sees as an acceleration of w^2 r — 3 mm a frame at 10 deg/frame and 10 cm).
//   At rest the two predict the same pose, so a still prop is smoothed exactly as by one model.
// - Manoeuvres: each axis whose innovation is improbable under the current covariance
//   (|y| > gate_sigma sigma) has its covariance inflated by the innovation itself (P_pos += y^2,
//   P_vel += (y/dt)^2), which makes the gain near 1 for that frame: the estimate jumps to the
//   measurement and the velocity follows (innovation-based adaptive estimation, in the manner of
//   Sage-Husa). The axis' group (rotation or position) takes the manoeuvre acceleration noise in
//   that frame and for manoeuvre_hold_s after, renewed at each gate trip and while an axis of the
//   group stays beyond manoeuvre_rearm_sigma sigma: hands accelerate over several frames (a
//   spin-up, a stop), and a stiff model re-armed only by the gate trails such a ramp by up to
//   gate_sigma sigma between trips. The price: for ~15 frames after a sudden start the estimate is
//   smoothed less (it relearns the velocity).
// Measurement noise per axis comes from the pose covariance of the solve (floored).
// Figures (tests/tracking/filter_test.cpp, generated poses at 24 fps with the crate's per-frame
// sigma 0.3 mm / 0.05 deg): a prop spun up at once to 10 deg/frame about an axis 10 cm from its
// origin trails by 0.10 mm / 0.016 deg at worst (0.34 sigma; before the screw model and the hold:
// 0.53 mm, 1.78 sigma); a still prop's jitter is unchanged (0.296 mm, 0.046 deg).
//
// Parameters (FilterOptions): accel_sigma_mps2 / angular_accel_sigma_radps2 — the white
// acceleration noise of the constant-velocity models (spectral density = sigma^2 * 1 s); lower =
// smoother; gate_sigma — innovations beyond this many sigmas count as a manoeuvre;
// manoeuvre_accel_sigma_mps2 / manoeuvre_angular_accel_sigma_radps2 — the acceleration noise while
// a manoeuvre holds (a hand's order; the figures hardly change at 3x these);
// manoeuvre_hold_s / manoeuvre_rearm_sigma — how long it holds after the last gate trip or
// innovation beyond the rearm level (0 s: the gated axes' inflation alone, as before issue 33);
// screw_model — mix in the screw model (false: the straight model alone); model_dwell_s — mean
// time the motion keeps to one model; min_position_sigma_m / min_rotation_sigma_rad — floors of the measurement noise (corners
// are never better than ~0.05 px); max_gap_s — longer without a measurement resets the filter.
#include <array>

#include <Eigen/Core>

#include "core/pose.h"

namespace previz::tracking {

struct FilterOptions {
  double accel_sigma_mps2 = 0.005;
  double angular_accel_sigma_radps2 = 0.01;
  double gate_sigma = 4.0;
  double manoeuvre_accel_sigma_mps2 = 3.0;
  double manoeuvre_angular_accel_sigma_radps2 = 10.0;
  double manoeuvre_hold_s = 0.1;
  double manoeuvre_rearm_sigma = 3.0;
  bool screw_model = true;
  double model_dwell_s = 1.0;
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
  // Pose extrapolated to time_s from the last update (meaningful only when initialised()): each
  // model's prediction, mixed by the models' probabilities.
  Pose predict(double time_s) const;
  // Feeds the measurement of time_s with its 6x6 covariance (rotation xyz, position xyz; see
  // solve.h). Returns the filtered pose at time_s.
  Pose update(double time_s, const Pose& measured, const Eigen::Matrix<double, 6, 6>& covariance);
  Eigen::Vector3d velocity() const { return vel_.tail<3>(); }          // m/s of the origin, world
  Eigen::Vector3d angularVelocity() const { return vel_.head<3>(); }  // rad/s, world axes
  // Axes (of 6: rotation xyz, position xyz) treated as a manoeuvre in the last update (gated, or
  // within a manoeuvre's hold) by the more probable model.
  int manoeuvreAxes() const { return manoeuvre_axes_; }
  // Probability of the screw model after the last update (0 when screw_model is off).
  double screwProbability() const { return models_ > 1 ? mu_[1] : 0.0; }

 private:
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  struct Model {
    Pose T = Pose::Identity();
    Vec6 vel = Vec6::Zero();  // rad/s (world axes), m/s of the origin (world)
    // Per axis 2x2 covariance [p pv; pv v] stored as (p, pv, v).
    Eigen::Matrix<double, 6, 3> P = Eigen::Matrix<double, 6, 3>::Zero();
    std::array<double, 2> hold_s{0.0, 0.0};  // manoeuvre hold left: rotation, position
    int manoeuvre_axes = 0;
  };
  Pose predictModel(const Model& m, int k, double dt) const;

  FilterOptions options_;
  int models_ = 1;  // m_[0]: straight; m_[1]: screw, when screw_model
  bool initialised_ = false;
  double time_s_ = 0;
  Pose T_ = Pose::Identity();
  Vec6 vel_ = Vec6::Zero();
  std::array<Model, 2> m_;
  std::array<double, 2> mu_{1.0, 0.0};  // model probabilities
  int manoeuvre_axes_ = 0;
};

}  // namespace previz::tracking
