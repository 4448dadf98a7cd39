#pragma once
// Generated prop motions for the pose filter (tests/tracking/filter_test.cpp and
// bench/tracking_bench.cpp): the true pose of every frame at 24 fps, measured as the truth
// perturbed by N(0, sigma^2) per axis — rotation as a left perturbation in world axes, position in
// world, as solve.h's covariance is defined — and that covariance handed to the filter. No
// rendering: the per-frame sigma of the joint solve is the input (the crate in the studio:
// ~0.3 mm / 0.05 deg, docs/formats.md's track output).
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "core/pose.h"
#include "tracking/filter.h"

namespace previz::tracking::test {

constexpr double kMotionFps = 24.0;

struct PropMotion {
  std::string name;
  std::vector<Pose> truth;  // per frame, time = frame / kMotionFps
  std::vector<int> onsets;  // last frame before each change of motion (spin-up, stop)
  int first_scored = 0;     // frames from here on are scored...
  int skip = 2;             // ...except the first `skip` frames after each onset
  bool scored(int f) const {
    if (f < first_scored) return false;
    for (int o : onsets)
      if (f > o && f <= o + skip) return false;
    return true;
  }
};

inline Eigen::Matrix3d motionExp(const Eigen::Vector3d& w) {
  const double a = w.norm();
  return a > 0 ? Eigen::AngleAxisd(a, w / a).toRotationMatrix() : Eigen::Matrix3d::Identity();
}
inline Eigen::Vector3d motionLog(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

// A prop standing 1.1 m up, tilted (any pose will do; not axis-aligned on purpose).
inline Pose motionStart() {
  Pose T = Pose::Identity();
  T.linear() = motionExp(Eigen::Vector3d(0.3, -0.2, 0.7));
  T.translation() << 0.4, -0.3, 1.1;
  return T;
}

// Still for 1 s, then a yaw (about world z) at deg_per_frame for 2 s, then still for 1 s. The
// axis passes pivot_m from the prop origin (0: through it; a prop turned in the hand turns about
// the hand). ramp_frames = 0: the rate starts and stops at once; n: it ramps linearly over n
// frames.
inline PropMotion turnMotion(double deg_per_frame, double pivot_m, int ramp_frames) {
  PropMotion m;
  m.name = "turn " + std::to_string(static_cast<int>(deg_per_frame)) + " deg/frame, axis " +
           std::to_string(static_cast<int>(std::lround(pivot_m * 100))) + " cm off the origin, " +
           (ramp_frames ? std::to_string(ramp_frames) + "-frame ramps" : std::string("sudden"));
  const int f0 = 24, hold = 48, frames = f0 + 2 * ramp_frames + hold + 24;
  const Pose start = motionStart();
  const Eigen::Vector3d pivot = start.translation() + Eigen::Vector3d(pivot_m, 0, 0);
  double angle_deg = 0;
  for (int f = 0; f < frames; ++f) {
    const int k = f - f0;  // moving frames so far
    double rate = 0;
    if (k <= 0) rate = 0;
    else if (k <= ramp_frames) rate = deg_per_frame * k / (ramp_frames + 1.0);
    else if (k <= ramp_frames + hold) rate = deg_per_frame;
    else if (k <= 2 * ramp_frames + hold) rate = deg_per_frame * (2 * ramp_frames + hold + 1 - k) / (ramp_frames + 1.0);
    angle_deg += rate;
    const Eigen::Matrix3d R = motionExp(Eigen::Vector3d(0, 0, angle_deg * M_PI / 180));
    Pose T = start;
    T.linear() = R * start.linear();
    T.translation() = pivot + R * (start.translation() - pivot);
    m.truth.push_back(T);
  }
  m.onsets = {f0, f0 + ramp_frames + hold};
  m.first_scored = f0 + 1;
  return m;
}

// filter_test's 1 m/s glide with a 1 rad/s turn about world z: at rest 1 s, a 2-frame ramp to
// full speed, 1.5 s at speed, a 2-frame stop, 1 s at rest.
inline PropMotion glideMotion() {
  PropMotion m;
  m.name = "glide 1 m/s + 1 rad/s";
  const Pose start = motionStart();
  const Eigen::Vector3d dir = Eigen::Vector3d(1, 0.3, 0).normalized();
  const double t0 = 1.0, ramp = 2 / kMotionFps, t1 = t0 + ramp + 1.5, t2 = t1 + ramp;
  auto distanceAt = [&](double t) {
    if (t <= t0) return 0.0;
    if (t <= t0 + ramp) return 0.5 * (t - t0) * (t - t0) / ramp;
    if (t <= t1) return 0.5 * ramp + (t - t0 - ramp);
    if (t <= t2) return 0.5 * ramp + (t1 - t0 - ramp) + (t - t1) - 0.5 * (t - t1) * (t - t1) / ramp;
    return 0.5 * ramp + (t1 - t0 - ramp) + 0.5 * ramp;
  };
  for (int f = 0; f < static_cast<int>(4.0 * kMotionFps); ++f) {
    const double d = distanceAt(f / kMotionFps);
    Pose T = start;
    T.translation() += d * dir;
    T.linear() = motionExp(Eigen::Vector3d(0, 0, d)) * start.linear();
    m.truth.push_back(T);
  }
  m.onsets = {static_cast<int>(std::lround(t0 * kMotionFps)), static_cast<int>(std::lround(t1 * kMotionFps))};
  m.first_scored = m.onsets[0] + 1;
  return m;
}

inline Eigen::Matrix<double, 6, 6> motionCovariance(double sigma_rotation_rad, double sigma_position_m) {
  Eigen::Matrix<double, 6, 1> d;
  d << Eigen::Vector3d::Constant(sigma_rotation_rad * sigma_rotation_rad),
      Eigen::Vector3d::Constant(sigma_position_m * sigma_position_m);
  return d.asDiagonal();
}

// Run `runs` noisy measurements of the motion (seeds seed, seed + 1, ...) through a fresh filter
// each.
// out(run, frame, filtered, truth, measured) for every frame.
template <class Out>
void runFilter(const PropMotion& m, const FilterOptions& options, double sigma_rotation_rad, double sigma_position_m,
               int runs, unsigned seed, Out&& out) {
  const Eigen::Matrix<double, 6, 6> cov = motionCovariance(sigma_rotation_rad, sigma_position_m);
  for (int run = 0; run < runs; ++run) {
    std::mt19937 rng(seed + static_cast<unsigned>(run));
    std::normal_distribution<double> n(0.0, 1.0);
    PoseFilter filter(options);
    for (int f = 0; f < static_cast<int>(m.truth.size()); ++f) {
      const Pose& truth = m.truth[static_cast<size_t>(f)];
      const Eigen::Vector3d nr(n(rng), n(rng), n(rng)), np(n(rng), n(rng), n(rng));
      Pose measured = truth;
      measured.linear() = motionExp(sigma_rotation_rad * nr) * truth.linear();
      measured.translation() += sigma_position_m * np;
      out(run, f, filter.update(f / kMotionFps, measured, cov), truth, measured);
    }
  }
}

inline double motionQuantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

// How the filtered pose follows the truth over the scored frames, in units of the per-frame sigma
// (per axis). Lag: the error averaged over the runs (the noise averages out, the trailing stays),
// its 3-D length, worst frame. Median and max: of the 3-D error of every scored frame of every run.
struct FollowFigures {
  double lag_rotation = 0, lag_position = 0;
  double median_rotation = 0, median_position = 0;
  double max_rotation = 0, max_position = 0;
  // The same of the measurements themselves (their 3-D error: median 1.54 sigma, above 4 sigma
  // once in a thousand frames).
  double measured_median_rotation = 0, measured_median_position = 0;
  double measured_max_rotation = 0, measured_max_position = 0;
};

inline FollowFigures followMotion(const PropMotion& m, const FilterOptions& options, double sigma_rotation_rad,
                                  double sigma_position_m, int runs, unsigned seed) {
  const size_t frames = m.truth.size();
  std::vector<Eigen::Vector3d> mean_r(frames, Eigen::Vector3d::Zero()), mean_p(frames, Eigen::Vector3d::Zero());
  std::vector<double> err_r, err_p, meas_r, meas_p;
  FollowFigures out;
  runFilter(m, options, sigma_rotation_rad, sigma_position_m, runs, seed,
            [&](int, int f, const Pose& filtered, const Pose& truth, const Pose& measured) {
              if (!m.scored(f)) return;
              meas_r.push_back(motionLog(measured.linear() * truth.linear().transpose()).norm() / sigma_rotation_rad);
              meas_p.push_back((measured.translation() - truth.translation()).norm() / sigma_position_m);
              const Eigen::Vector3d er = motionLog(filtered.linear() * truth.linear().transpose()) / sigma_rotation_rad;
              const Eigen::Vector3d ep = (filtered.translation() - truth.translation()) / sigma_position_m;
              mean_r[static_cast<size_t>(f)] += er / runs;
              mean_p[static_cast<size_t>(f)] += ep / runs;
              err_r.push_back(er.norm());
              err_p.push_back(ep.norm());
            });
  for (size_t f = 0; f < frames; ++f) {
    out.lag_rotation = std::max(out.lag_rotation, mean_r[f].norm());
    out.lag_position = std::max(out.lag_position, mean_p[f].norm());
  }
  out.median_rotation = motionQuantile(err_r, 0.5);
  out.median_position = motionQuantile(err_p, 0.5);
  out.max_rotation = motionQuantile(err_r, 1.0);
  out.max_position = motionQuantile(err_p, 1.0);
  out.measured_median_rotation = motionQuantile(meas_r, 0.5);
  out.measured_median_position = motionQuantile(meas_p, 0.5);
  out.measured_max_rotation = motionQuantile(meas_r, 1.0);
  out.measured_max_position = motionQuantile(meas_p, 1.0);
  return out;
}

struct Spread {
  double position_m = 0, rotation_rad = 0;
};
// RMS distance of the poses from their mean position / rotation (3-D, not per axis).
inline Spread poseSpread(const std::vector<Pose>& poses) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero(), w_mean = Eigen::Vector3d::Zero();
  const Eigen::Matrix3d R0 = poses[0].linear();
  for (const Pose& p : poses) {
    mean += p.translation();
    w_mean += motionLog(p.linear() * R0.transpose());
  }
  mean /= static_cast<double>(poses.size());
  w_mean /= static_cast<double>(poses.size());
  double sp = 0, sr = 0;
  for (const Pose& p : poses) {
    sp += (p.translation() - mean).squaredNorm();
    sr += (motionLog(p.linear() * R0.transpose()) - w_mean).squaredNorm();
  }
  return {std::sqrt(sp / poses.size()), std::sqrt(sr / poses.size())};
}

// A still prop as filter_test's rendered one is scored: the spread of the filtered pose over 100
// frames after 10 frames of warm-up, averaged over the runs.
inline Spread stillJitter(const FilterOptions& options, double sigma_rotation_rad, double sigma_position_m, int runs,
                          unsigned seed) {
  constexpr int kWarmup = 10, kFrames = 100;
  PropMotion m;
  m.truth.assign(kWarmup + kFrames, motionStart());
  std::vector<std::vector<Pose>> filtered(static_cast<size_t>(runs));
  runFilter(m, options, sigma_rotation_rad, sigma_position_m, runs, seed, [&](int run, int f, const Pose& p, const Pose&, const Pose&) {
    if (f >= kWarmup) filtered[static_cast<size_t>(run)].push_back(p);
  });
  Spread out;
  for (const auto& poses : filtered) {
    const Spread s = poseSpread(poses);
    out.position_m += s.position_m / runs;
    out.rotation_rad += s.rotation_rad / runs;
  }
  return out;
}

// The filter before issue 33 (one straight model, the gate alone): kept reachable through the
// options so the figures before and after can be measured side by side.
inline FilterOptions legacyFilterOptions() {
  FilterOptions o;
  o.screw_model = false;
  o.manoeuvre_hold_s = 0;
  return o;
}

}  // namespace previz::tracking::test
