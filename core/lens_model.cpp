#include "core/lens_model.h"

#include <algorithm>
#include <cmath>

namespace previz::lens {

namespace {
constexpr double kHalfPi = 1.5707963267948966;
// Where theta_d stops increasing is bracketed on this grid of [0, pi/2], then bisected.
constexpr int kTurnSamples = 2048;
}  // namespace

double kannalaBrandtMaxTheta(double k1, double k2, double k3, double k4) {
  double lo = 0;
  for (int i = 1; i <= kTurnSamples; ++i) {
    const double t = kHalfPi * i / kTurnSamples;
    if (kannalaBrandtThetaSlope(k1, k2, k3, k4, t) > 0) {
      lo = t;
      continue;
    }
    double hi = t;
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (lo + hi);
      (kannalaBrandtThetaSlope(k1, k2, k3, k4, mid) > 0 ? lo : hi) = mid;
    }
    return lo;
  }
  return kHalfPi;  // increasing all the way: every angle short of 90 degrees
}

KannalaBrandtInverse kannalaBrandtUndistort(double k1, double k2, double k3, double k4, double xd, double yd,
                                            double max_theta, int max_iterations, double tolerance) {
  KannalaBrandtInverse out;
  const double theta_d = std::hypot(xd, yd);
  if (theta_d == 0) {
    out.status = InverseStatus::kConverged;
    return out;
  }
  // theta_d(theta) increases on [0, max_theta): one root below it, or none.
  if (!(theta_d < kannalaBrandtTheta(k1, k2, k3, k4, max_theta))) {
    out.status = InverseStatus::kNotInvertible;
    out.residual = theta_d - kannalaBrandtTheta(k1, k2, k3, k4, max_theta);
    return out;
  }
  // Newton, kept inside the bracket [lo, hi] (a bisection step when it would leave it).
  double lo = 0, hi = max_theta;
  double theta = std::clamp(theta_d, 0.0, max_theta * (1 - 1e-12));
  for (out.iterations = 0; out.iterations < max_iterations; ++out.iterations) {
    const double f = kannalaBrandtTheta(k1, k2, k3, k4, theta) - theta_d;
    out.residual = std::abs(f);
    if (out.residual <= tolerance) break;
    (f > 0 ? hi : lo) = theta;
    const double slope = kannalaBrandtThetaSlope(k1, k2, k3, k4, theta);
    double next = theta - f / slope;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (next == theta) break;
    theta = next;
  }
  out.residual = std::abs(kannalaBrandtTheta(k1, k2, k3, k4, theta) - theta_d);
  if (!(theta < kHalfPi)) {
    out.status = InverseStatus::kNotInvertible;
    return out;
  }
  out.status = out.residual <= tolerance ? InverseStatus::kConverged : InverseStatus::kNotConverged;
  const double scale = std::tan(theta) / theta_d;
  out.x = xd * scale;
  out.y = yd * scale;
  return out;
}

}  // namespace previz::lens
