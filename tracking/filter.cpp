// Constant-velocity Kalman filter on SE(3) with manoeuvre adaptation (see filter.h).
#include "tracking/filter.h"

#include <cmath>

#include <Eigen/Geometry>

#include "core/error.h"

namespace previz::tracking {

namespace {

Eigen::Matrix3d expSO3(const Eigen::Vector3d& w) {
  const double a = w.norm();
  return a > 0 ? Eigen::AngleAxisd(a, w / a).toRotationMatrix() : Eigen::Matrix3d::Identity();
}

Eigen::Vector3d logSO3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

}  // namespace

void FilterOptions::validate() const {
  auto bad = [](const std::string& f, const std::string& what) {
    ErrorContext c;
    c.field = f;
    throw Error("filter: " + what, c);
  };
  if (!(accel_sigma_mps2 > 0)) bad("accel_sigma_mps2", "accel_sigma_mps2 must be > 0");
  if (!(angular_accel_sigma_radps2 > 0)) bad("angular_accel_sigma_radps2", "angular_accel_sigma_radps2 must be > 0");
  if (!(gate_sigma > 0)) bad("gate_sigma", "gate_sigma must be > 0");
  if (!(min_position_sigma_m > 0)) bad("min_position_sigma_m", "min_position_sigma_m must be > 0");
  if (!(min_rotation_sigma_rad > 0)) bad("min_rotation_sigma_rad", "min_rotation_sigma_rad must be > 0");
  if (!(max_gap_s > 0)) bad("max_gap_s", "max_gap_s must be > 0");
}

PoseFilter::PoseFilter(const FilterOptions& options) : options_(options) { options_.validate(); }

Pose PoseFilter::predict(double time_s) const {
  const double dt = time_s - time_s_;
  Pose T = T_;
  T.linear() = expSO3(vel_.head<3>() * dt) * T_.linear();
  T.translation() = T_.translation() + vel_.tail<3>() * dt;
  return T;
}

Pose PoseFilter::update(double time_s, const Pose& measured, const Eigen::Matrix<double, 6, 6>& covariance) {
  manoeuvre_axes_ = 0;
  const double dt = time_s - time_s_;
  if (!initialised_ || dt <= 0 || dt > options_.max_gap_s) {
    initialised_ = true;
    time_s_ = time_s;
    T_ = measured;
    vel_.setZero();
    for (int i = 0; i < 6; ++i) {
      const double floor = i < 3 ? options_.min_rotation_sigma_rad : options_.min_position_sigma_m;
      const double r = std::max(covariance(i, i), floor * floor);
      // Velocity unknown: a prop picked up at 2 m/s (or 3 rad/s) is within one sigma.
      const double v = i < 3 ? 3.0 : 2.0;
      P_.row(i) << r, 0.0, v * v;
    }
    return T_;
  }
  const Pose pred = predict(time_s);
  Eigen::Matrix<double, 6, 1> y;
  y.head<3>() = logSO3(measured.linear() * pred.linear().transpose());
  y.tail<3>() = measured.translation() - pred.translation();
  Eigen::Matrix<double, 6, 1> dx, dv;
  for (int i = 0; i < 6; ++i) {
    const double qa = i < 3 ? options_.angular_accel_sigma_radps2 : options_.accel_sigma_mps2;
    const double q = qa * qa;
    // Predict: F = [1 dt; 0 1], Q = q [dt^3/3 dt^2/2; dt^2/2 dt].
    double p = P_(i, 0), pv = P_(i, 1), v = P_(i, 2);
    p = p + 2 * dt * pv + dt * dt * v + q * dt * dt * dt / 3;
    pv = pv + dt * v + q * dt * dt / 2;
    v = v + q * dt;
    const double floor = i < 3 ? options_.min_rotation_sigma_rad : options_.min_position_sigma_m;
    const double r = std::max(covariance(i, i), floor * floor);
    const double s = p + r;
    if (y[i] * y[i] > options_.gate_sigma * options_.gate_sigma * s) {
      // Manoeuvre: the model no longer explains the motion; let this measurement through.
      // Attribute the innovation to a velocity error: position, velocity and their correlation
      // all grow, so both gains approach their one-step values (k0 -> 1, k1 -> 1/dt).
      p += y[i] * y[i];
      pv += y[i] * y[i] / dt;
      v += (y[i] / dt) * (y[i] / dt);
      ++manoeuvre_axes_;
    }
    const double k0 = p / (p + r), k1 = pv / (p + r);
    dx[i] = k0 * y[i];
    dv[i] = k1 * y[i];
    P_(i, 0) = (1 - k0) * p;
    P_(i, 1) = (1 - k0) * pv;
    P_(i, 2) = v - k1 * pv;
  }
  T_.linear() = expSO3(dx.head<3>()) * pred.linear();
  T_.translation() = pred.translation() + dx.tail<3>();
  vel_ += dv;
  time_s_ = time_s;
  return T_;
}

}  // namespace previz::tracking
