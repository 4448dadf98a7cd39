// Constant-velocity Kalman filters on SE(3), straight and screw models mixed as an IMM, with
// manoeuvre adaptation (see filter.h).
#include "tracking/filter.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Geometry>

#include "core/error.h"

namespace previz::tracking {

namespace {

using Vec6 = Eigen::Matrix<double, 6, 1>;

Eigen::Matrix3d hat(const Eigen::Vector3d& w) {
  Eigen::Matrix3d W;
  W << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return W;
}

Eigen::Matrix3d expSO3(const Eigen::Vector3d& w) {
  const double a = w.norm();
  return a > 0 ? Eigen::AngleAxisd(a, w / a).toRotationMatrix() : Eigen::Matrix3d::Identity();
}

Eigen::Vector3d logSO3(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

// Left Jacobian of SO(3): a point turning at w for unit time while moving at v (in the turning
// frame) travels J(w) v.
Eigen::Matrix3d leftJacobianSO3(const Eigen::Vector3d& w) {
  const double a = w.norm();
  const Eigen::Matrix3d W = hat(w);
  if (a < 1e-6) return Eigen::Matrix3d::Identity() + 0.5 * W + W * W / 6.0;
  return Eigen::Matrix3d::Identity() + (1 - std::cos(a)) / (a * a) * W + (a - std::sin(a)) / (a * a * a) * W * W;
}

// T relative to ref on the filter's tangent space: rotation left perturbation (world axes),
// position difference (world).
Vec6 offset(const Pose& T, const Pose& ref) {
  Vec6 d;
  d.head<3>() = logSO3(T.linear() * ref.linear().transpose());
  d.tail<3>() = T.translation() - ref.translation();
  return d;
}

Pose applyOffset(const Vec6& d, const Pose& ref) {
  Pose T = ref;
  T.linear() = expSO3(d.head<3>()) * ref.linear();
  T.translation() = ref.translation() + d.tail<3>();
  return T;
}

}  // namespace

void FilterOptions::validate() const {
  auto bad = [](const std::string& f, const std::string& what, double got) {
    ErrorContext c;
    c.field = f;
    throw Error("filter: " + what + " (got " + std::to_string(got) + ")", c);
  };
  auto positive = [&](const char* f, double v) {
    if (!(v > 0) || !std::isfinite(v)) bad(f, std::string(f) + " must be > 0", v);
  };
  positive("accel_sigma_mps2", accel_sigma_mps2);
  positive("angular_accel_sigma_radps2", angular_accel_sigma_radps2);
  positive("gate_sigma", gate_sigma);
  positive("manoeuvre_accel_sigma_mps2", manoeuvre_accel_sigma_mps2);
  positive("manoeuvre_angular_accel_sigma_radps2", manoeuvre_angular_accel_sigma_radps2);
  if (!(manoeuvre_hold_s >= 0) || !std::isfinite(manoeuvre_hold_s))
    bad("manoeuvre_hold_s", "manoeuvre_hold_s must be >= 0", manoeuvre_hold_s);
  positive("manoeuvre_rearm_sigma", manoeuvre_rearm_sigma);
  positive("model_dwell_s", model_dwell_s);
  positive("min_position_sigma_m", min_position_sigma_m);
  positive("min_rotation_sigma_rad", min_rotation_sigma_rad);
  positive("max_gap_s", max_gap_s);
}

PoseFilter::PoseFilter(const FilterOptions& options) : options_(options) {
  options_.validate();
  models_ = options_.screw_model ? 2 : 1;
}

Pose PoseFilter::predictModel(const Model& m, int k, double dt) const {
  const Eigen::Vector3d phi = m.vel.head<3>() * dt;
  Pose T = m.T;
  T.linear() = expSO3(phi) * m.T.linear();
  T.translation() = m.T.translation() +
                    (k == 1 ? Eigen::Vector3d(leftJacobianSO3(phi) * m.vel.tail<3>() * dt) : Eigen::Vector3d(m.vel.tail<3>() * dt));
  return T;
}

Pose PoseFilter::predict(double time_s) const {
  const double dt = time_s - time_s_;
  const Pose p0 = predictModel(m_[0], 0, dt);
  if (models_ == 1) return p0;
  return applyOffset(mu_[1] * offset(predictModel(m_[1], 1, dt), p0), p0);
}

Pose PoseFilter::update(double time_s, const Pose& measured, const Eigen::Matrix<double, 6, 6>& covariance) {
  manoeuvre_axes_ = 0;
  const double dt = time_s - time_s_;
  Vec6 r;  // measurement variance per axis, floored
  for (int i = 0; i < 6; ++i) {
    const double floor = i < 3 ? options_.min_rotation_sigma_rad : options_.min_position_sigma_m;
    r[i] = std::max(covariance(i, i), floor * floor);
  }
  if (!initialised_ || dt <= 0 || dt > options_.max_gap_s) {
    initialised_ = true;
    time_s_ = time_s;
    T_ = measured;
    vel_.setZero();
    for (int k = 0; k < models_; ++k) {
      Model& m = m_[static_cast<size_t>(k)];
      m = Model{};
      m.T = measured;
      for (int i = 0; i < 6; ++i) {
        // Velocity unknown: a prop picked up at 2 m/s (or 3 rad/s) is within one sigma.
        const double v = i < 3 ? 3.0 : 2.0;
        m.P.row(i) << r[i], 0.0, v * v;
      }
    }
    mu_ = models_ == 1 ? std::array<double, 2>{1.0, 0.0} : std::array<double, 2>{0.5, 0.5};
    return T_;
  }

  // IMM mixing (Blom & Bar-Shalom 1988): each model starts this frame from the blend of both
  // models' estimates, weighted by how likely the motion switched into it. Blends are taken on
  // the tangent space around the last combined estimate T_.
  std::array<double, 2> c{1.0, 0.0};
  if (models_ == 2) {
    const double stay = std::exp(-dt / options_.model_dwell_s);
    const double pi[2][2] = {{stay, 1 - stay}, {1 - stay, stay}};  // pi[i][j]: from i to j
    const Vec6 d[2] = {offset(m_[0].T, T_), offset(m_[1].T, T_)};
    std::array<Model, 2> mixed = m_;
    for (int j = 0; j < 2; ++j) {
      c[j] = pi[0][j] * mu_[0] + pi[1][j] * mu_[1];
      const double w[2] = {pi[0][j] * mu_[0] / c[j], pi[1][j] * mu_[1] / c[j]};
      const Vec6 d0 = w[0] * d[0] + w[1] * d[1];
      const Vec6 v0 = w[0] * m_[0].vel + w[1] * m_[1].vel;
      Model& mj = mixed[static_cast<size_t>(j)];
      mj.P.setZero();
      for (int i = 0; i < 2; ++i) {
        const Vec6 ex = d[i] - d0, ev = m_[static_cast<size_t>(i)].vel - v0;
        mj.P.col(0) += w[i] * (m_[static_cast<size_t>(i)].P.col(0) + ex.cwiseProduct(ex));
        mj.P.col(1) += w[i] * (m_[static_cast<size_t>(i)].P.col(1) + ex.cwiseProduct(ev));
        mj.P.col(2) += w[i] * (m_[static_cast<size_t>(i)].P.col(2) + ev.cwiseProduct(ev));
      }
      mj.T = applyOffset(d0, T_);
      mj.vel = v0;
    }
    m_ = mixed;
  }

  std::array<double, 2> log_likelihood{0.0, 0.0};
  for (int k = 0; k < models_; ++k) {
    Model& m = m_[static_cast<size_t>(k)];
    const Pose pred = predictModel(m, k, dt);
    // Screw: the origin's velocity turns with the body.
    if (k == 1) m.vel.tail<3>() = expSO3(m.vel.head<3>() * dt) * m.vel.tail<3>().eval();
    const Vec6 y = offset(measured, pred);
    // Gate and manoeuvre, per group (rotation, position): the predicted mean does not depend on
    // the process noise, so this frame's innovation can choose it. A group with a gated axis, or
    // within manoeuvre_hold_s of one, takes the manoeuvre acceleration noise; the hold restarts at
    // each gate trip and while an axis of the group stays beyond the rearm level (the
    // acceleration goes on).
    auto predictP = [&](int i, double qa, double& p, double& pv, double& v) {
      // F = [1 dt; 0 1], Q = q [dt^3/3 dt^2/2; dt^2/2 dt].
      const double q = qa * qa;
      p = m.P(i, 0) + 2 * dt * m.P(i, 1) + dt * dt * m.P(i, 2) + q * dt * dt * dt / 3;
      pv = m.P(i, 1) + dt * m.P(i, 2) + q * dt * dt / 2;
      v = m.P(i, 2) + q * dt;
    };
    const double steady_q[2] = {options_.angular_accel_sigma_radps2, options_.accel_sigma_mps2};
    const double manoeuvre_q[2] = {options_.manoeuvre_angular_accel_sigma_radps2, options_.manoeuvre_accel_sigma_mps2};
    bool gated[6];
    bool tripped[2] = {false, false}, going_on[2] = {false, false}, manoeuvre[2];
    for (int i = 0; i < 6; ++i) {
      const int g = i / 3;  // 0: rotation, 1: position
      double p, pv, v;
      predictP(i, steady_q[g], p, pv, v);
      const double s = p + r[i];
      log_likelihood[static_cast<size_t>(k)] -= 0.5 * (y[i] * y[i] / s + std::log(2 * M_PI * s));
      gated[i] = y[i] * y[i] > options_.gate_sigma * options_.gate_sigma * s;
      tripped[g] = tripped[g] || gated[i];
      going_on[g] = going_on[g] || (m.hold_s[static_cast<size_t>(g)] > 0 &&
                                     y[i] * y[i] > options_.manoeuvre_rearm_sigma * options_.manoeuvre_rearm_sigma * s);
    }
    bool renew[2];
    for (int g = 0; g < 2; ++g) {
      renew[g] = tripped[g] || going_on[g];
      manoeuvre[g] = tripped[g] || m.hold_s[static_cast<size_t>(g)] > 0;
    }
    // manoeuvre_hold_s = 0: the gated axes' inflation alone (the filter before issue 33).
    const bool adapt = options_.manoeuvre_hold_s > 0;
    m.manoeuvre_axes = 0;
    Vec6 dx, dv;
    for (int i = 0; i < 6; ++i) {
      const int g = i / 3;
      double p, pv, v;
      predictP(i, adapt && manoeuvre[g] ? manoeuvre_q[g] : steady_q[g], p, pv, v);
      if (gated[i]) {
        // The model no longer explains the motion; let this measurement through. Attribute the
        // innovation to a velocity error: position, velocity and their correlation all grow, so
        // both gains approach their one-step values (k0 -> 1, k1 -> 1/dt).
        p += y[i] * y[i];
        pv += y[i] * y[i] / dt;
        v += (y[i] / dt) * (y[i] / dt);
      }
      if (gated[i] || (adapt && manoeuvre[g])) ++m.manoeuvre_axes;
      const double k0 = p / (p + r[i]), k1 = pv / (p + r[i]);
      dx[i] = k0 * y[i];
      dv[i] = k1 * y[i];
      m.P(i, 0) = (1 - k0) * p;
      m.P(i, 1) = (1 - k0) * pv;
      m.P(i, 2) = v - k1 * pv;
    }
    for (int g = 0; g < 2; ++g)
      m.hold_s[static_cast<size_t>(g)] =
          renew[g] ? options_.manoeuvre_hold_s : std::max(0.0, m.hold_s[static_cast<size_t>(g)] - dt);
    m.T = applyOffset(dx, pred);
    m.vel += dv;
  }

  if (models_ == 2) {
    // Model probabilities: prior (mixing) times measurement likelihood, normalised in logs; a
    // floor keeps either model able to take over.
    const double l0 = log_likelihood[0] + std::log(c[0]), l1 = log_likelihood[1] + std::log(c[1]);
    const double top = std::max(l0, l1);
    double m0 = std::exp(l0 - top), m1 = std::exp(l1 - top);
    const double sum = m0 + m1;
    m0 = std::max(1e-6, m0 / sum);
    m1 = std::max(1e-6, m1 / sum);
    mu_ = {m0 / (m0 + m1), m1 / (m0 + m1)};
    T_ = applyOffset(mu_[1] * offset(m_[1].T, m_[0].T), m_[0].T);
    vel_ = mu_[0] * m_[0].vel + mu_[1] * m_[1].vel;
    manoeuvre_axes_ = m_[mu_[1] > mu_[0] ? 1 : 0].manoeuvre_axes;
  } else {
    T_ = m_[0].T;
    vel_ = m_[0].vel;
    manoeuvre_axes_ = m_[0].manoeuvre_axes;
  }
  time_s_ = time_s;
  return T_;
}

}  // namespace previz::tracking
