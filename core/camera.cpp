#include "core/camera.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/LU>

#include "core/error.h"

namespace previz {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// h(s) = d/dr [r radial(r)] with s = r^2: the radial map r -> r (1 + k1 r^2 + k2 r^4 + k3 r^6)
// is increasing exactly where h > 0.
inline double radialSlope(const Distortion& d, double s) {
  return 1.0 + s * (3.0 * d.k1 + s * (5.0 * d.k2 + s * (7.0 * d.k3)));
}

// Positive roots of h'(s) = 3 k1 + 10 k2 s + 21 k3 s^2 (where h can turn), ascending.
int slopeCriticalPoints(const Distortion& d, double out[2]) {
  const double a = 21.0 * d.k3, b = 10.0 * d.k2, c = 3.0 * d.k1;
  double roots[2];
  int n = 0;
  if (a == 0.0) {
    if (b != 0.0) roots[n++] = -c / b;
  } else {
    const double disc = b * b - 4.0 * a * c;
    if (disc >= 0.0) {
      // Stable form: no cancellation between b and sqrt(disc).
      const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
      if (q != 0.0) {
        roots[n++] = q / a;
        roots[n++] = c / q;
      } else {
        roots[n++] = 0.0;  // b = c = 0
      }
    }
  }
  int m = 0;
  for (int i = 0; i < n; ++i)
    if (roots[i] > 0.0 && std::isfinite(roots[i])) out[m++] = roots[i];
  if (m == 2 && out[0] > out[1]) std::swap(out[0], out[1]);
  return m;
}

// True when h > 0 on all of [0, s], i.e. r = sqrt(s) lies below the turning radius. O(1): h is
// a cubic, so it is enough to look at s and at the interior critical points.
bool radialIncreasingUpTo(const Distortion& d, double s) {
  if (!(s >= 0.0)) return false;
  if (d.k1 >= 0.0 && d.k2 >= 0.0 && d.k3 >= 0.0) return std::isfinite(s);
  if (!(radialSlope(d, s) > 0.0)) return false;
  double crit[2];
  const int n = slopeCriticalPoints(d, crit);
  for (int i = 0; i < n; ++i)
    if (crit[i] < s && !(radialSlope(d, crit[i]) > 0.0)) return false;
  return true;
}

// Smallest s > 0 with h(s) <= 0 (the squared turning radius), +inf when there is none.
double turningRadiusSquared(const Distortion& d) {
  if (d.k1 >= 0.0 && d.k2 >= 0.0 && d.k3 >= 0.0) return kInf;
  double crit[2];
  const int n = slopeCriticalPoints(d, crit);
  // Bracket [lo, hi] on which h is monotone with h(lo) > 0 >= h(hi).
  double lo = 0.0, hi = kInf;
  for (int i = 0; i < n; ++i) {
    if (!(radialSlope(d, crit[i]) > 0.0)) {
      hi = crit[i];
      break;
    }
    lo = crit[i];
  }
  if (hi == kInf) {
    // Past the last critical point h is monotone; it reaches zero only if the leading
    // coefficient is negative. All roots lie within Cauchy's bound 1 + max|a_i / a_n|.
    const double a[4] = {1.0, 3.0 * d.k1, 5.0 * d.k2, 7.0 * d.k3};
    int deg = 3;
    while (deg > 0 && a[deg] == 0.0) --deg;
    if (deg == 0 || a[deg] > 0.0) return kInf;
    double bound = 0.0;
    for (int i = 0; i < deg; ++i) bound = std::max(bound, std::abs(a[i] / a[deg]));
    hi = std::max(lo, 1.0 + bound);
    if (!std::isfinite(hi)) return kInf;  // overflow: turning point beyond any real lens
  }
  // Safeguarded Newton (bisection fallback) on the monotone bracket.
  double s = 0.5 * (lo + hi);
  for (int it = 0; it < 200; ++it) {
    const double h = radialSlope(d, s);
    if (h > 0.0) lo = s; else hi = s;
    const double dh = 3.0 * d.k1 + s * (10.0 * d.k2 + s * (21.0 * d.k3));
    double next = (dh != 0.0) ? s - h / dh : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (next == s || hi - lo <= 4.0 * std::numeric_limits<double>::epsilon() * hi) break;
    s = next;
  }
  // Snap to the smallest double the O(1) predicate rejects, so that project() (which uses the
  // predicate) and the inverse (which compares with this value) agree to the last bit.
  s = hi;
  for (int i = 0; i < 64 && radialIncreasingUpTo(d, s); ++i) s = std::nextafter(s, kInf);
  for (int i = 0; i < 64; ++i) {
    const double below = std::nextafter(s, 0.0);
    if (radialIncreasingUpTo(d, below)) break;
    s = below;
  }
  return s;
}

// ---- The rational Brown–Conrady domain (k4 k5 k6 not all 0) ---------------------------------
// With radial = N(s) / D(s) (s = r^2), d/dr [r radial] = P(s) / D(s)^2 where
//   P = N D + 2 s (N' D - N D')   (degree <= 6 in s)
// so the radial map is increasing exactly while P > 0 and D > 0 (a zero of D is a pole of the
// factor: the domain ends there too). The plain model keeps its closed-form cubic above (and so
// its numbers); the rational one finds the first sign change of P and D by isolating the real
// roots of each polynomial between those of its derivative (recursively down to degree 1):
// exact in the sense that no narrow dip between samples can be missed.

inline double horner(const double* c, int deg, double s) {
  double v = c[deg];
  for (int i = deg - 1; i >= 0; --i) v = v * s + c[i];
  return v;
}

// The real roots of c (degree deg, c[deg] != 0) in (0, bound), ascending, where c changes sign
// or touches zero at a root of its derivative. At most deg of them.
int rootsInRange(const double* c, int deg, double bound, double* out) {
  if (deg <= 0) return 0;
  if (deg == 1) {
    const double r = -c[0] / c[1];
    if (r > 0.0 && r < bound) {
      out[0] = r;
      return 1;
    }
    return 0;
  }
  double dc[6];
  for (int i = 1; i <= deg; ++i) dc[i - 1] = i * c[i];
  double ends[8];
  int n = 0;
  ends[n++] = 0.0;
  n += rootsInRange(dc, deg - 1, bound, ends + n);
  ends[n++] = bound;
  // c is monotone between consecutive ends: at most one root in each, found by bisection.
  int m = 0;
  for (int i = 0; i + 1 < n; ++i) {
    double lo = ends[i], hi = ends[i + 1];
    const double flo = horner(c, deg, lo), fhi = horner(c, deg, hi);
    if (flo == 0.0) {
      if (lo > 0.0 && (m == 0 || out[m - 1] != lo)) out[m++] = lo;
      continue;
    }
    if ((flo > 0.0) == (fhi > 0.0) && fhi != 0.0) continue;
    const bool rising = flo < 0.0;
    for (int it = 0; it < 2200; ++it) {
      const double mid = 0.5 * (lo + hi);
      if (!(mid > lo && mid < hi)) break;
      ((horner(c, deg, mid) < 0.0) == rising ? lo : hi) = mid;
    }
    out[m++] = hi;
  }
  return m;
}

// Smallest s > 0 with c(s) <= 0, given c(0) = c[0] = 1 > 0; +inf when there is none.
double firstNonPositive(const double* coeffs, int deg) {
  double c[7];
  for (int i = 0; i <= deg; ++i) c[i] = coeffs[i];
  while (deg > 0 && c[deg] == 0.0) --deg;
  if (deg == 0) return kInf;
  // Every root lies within Cauchy's bound 1 + max |c_i / c_deg|; past it c has c[deg]'s sign.
  double bound = 0.0;
  for (int i = 0; i < deg; ++i) bound = std::max(bound, std::abs(c[i] / c[deg]));
  bound = 1.0 + bound;
  if (!std::isfinite(bound)) return kInf;  // a turning point beyond any real lens
  bound *= 2.0;
  // c > 0 up to its first root; the bisection returns the end where c <= 0.
  double roots[6];
  return rootsInRange(c, deg, bound, roots) > 0 ? roots[0] : kInf;
}

// The squared turning radius of a rational Brown–Conrady lens: min(first s with P <= 0, first s
// with D <= 0).
double rationalTurningRadiusSquaredUncached(const Distortion& d) {
  const double N[4] = {1.0, d.k1, d.k2, d.k3}, D[4] = {1.0, d.k4, d.k5, d.k6};
  const double sN1[4] = {0.0, d.k1, 2.0 * d.k2, 3.0 * d.k3}, sD1[4] = {0.0, d.k4, 2.0 * d.k5, 3.0 * d.k6};
  double P[7] = {0, 0, 0, 0, 0, 0, 0};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) P[i + j] += N[i] * D[j] + 2.0 * (sN1[i] * D[j] - N[i] * sD1[j]);
  return std::min(firstNonPositive(P, 6), firstNonPositive(D, 3));
}

// The same, remembered for the last lens a thread asked about (project() checks the domain of
// every point).
double rationalTurningRadiusSquared(const Distortion& d) {
  thread_local double key[6] = {std::numeric_limits<double>::quiet_NaN(), 0, 0, 0, 0, 0};
  thread_local double value = 0;
  if (!(key[0] == d.k1 && key[1] == d.k2 && key[2] == d.k3 && key[3] == d.k4 && key[4] == d.k5 &&
        key[5] == d.k6)) {
    value = rationalTurningRadiusSquaredUncached(d);
    key[0] = d.k1;
    key[1] = d.k2;
    key[2] = d.k3;
    key[3] = d.k4;
    key[4] = d.k5;
    key[5] = d.k6;
  }
  return value;
}

// The Brown–Conrady domain for either form: the plain model's closed form, or the rational one.
double brownTurningRadiusSquared(const Distortion& d) {
  return d.isRational() ? rationalTurningRadiusSquared(d) : turningRadiusSquared(d);
}

bool brownIncreasingUpTo(const Distortion& d, double s) {
  if (!d.isRational()) return radialIncreasingUpTo(d, s);
  return s >= 0.0 && s < rationalTurningRadiusSquared(d);
}

struct DistortEval {
  double xd, yd;
};

inline DistortEval distortXY(const Distortion& d, double x, double y) {
  DistortEval e;
  if (d.model == LensModel::kKannalaBrandt)
    lens::kannalaBrandtDistort(d.k1, d.k2, d.k3, d.k4, x, y, e.xd, e.yd);
  else if (d.isRational())
    lens::brownDistort(d.k1, d.k2, d.p1, d.p2, d.k3, d.k4, d.k5, d.k6, x, y, e.xd, e.yd);
  else
    lens::brownDistort<false>(d.k1, d.k2, d.p1, d.p2, d.k3, 0.0, 0.0, 0.0, x, y, e.xd, e.yd);
  return e;
}

// The Jacobian of the Brown model is symmetric (it is the gradient of a potential).
struct Jacobian {
  double xx, xy, yy;
  double det() const { return xx * yy - xy * xy; }
};

inline Jacobian distortJacobianXY(const Distortion& d, double x, double y) {
  Jacobian j;
  double xd, yd;
  if (d.model == LensModel::kKannalaBrandt)
    lens::kannalaBrandtDistortWithJacobian(d.k1, d.k2, d.k3, d.k4, x, y, xd, yd, j.xx, j.xy, j.yy);
  else if (d.isRational())
    lens::brownDistortWithJacobian(d.k1, d.k2, d.p1, d.p2, d.k3, d.k4, d.k5, d.k6, x, y, xd, yd, j.xx, j.xy,
                                   j.yy);
  else
    lens::brownDistortWithJacobian<false>(d.k1, d.k2, d.p1, d.p2, d.k3, 0.0, 0.0, 0.0, x, y, xd, yd, j.xx, j.xy,
                                          j.yy);
  return j;
}

// Kannala–Brandt's largest angle (lens::kannalaBrandtMaxTheta), remembered for the last lens a
// thread asked about: project() checks the domain of every point and the search costs about two
// thousand polynomial evaluations.
double kbMaxTheta(const Distortion& d) {
  thread_local double key[4] = {std::numeric_limits<double>::quiet_NaN(), 0, 0, 0};
  thread_local double value = 0;
  if (!(key[0] == d.k1 && key[1] == d.k2 && key[2] == d.k3 && key[3] == d.k4)) {
    value = lens::kannalaBrandtMaxTheta(d.k1, d.k2, d.k3, d.k4);
    key[0] = d.k1;
    key[1] = d.k2;
    key[2] = d.k3;
    key[3] = d.k4;
  }
  return value;
}

// The squared ideal radius of the Kannala–Brandt domain: tan^2 of its largest angle (+inf at 90
// degrees).
double kbRadiusSquared(double max_theta) {
  constexpr double kHalfPi = 1.5707963267948966;
  if (!(max_theta < kHalfPi)) return kInf;
  const double r = std::tan(max_theta);
  return r * r;
}

inline bool inDomainXY(const Distortion& d, bool tangential, double s_max, double x, double y) {
  const double r2 = x * x + y * y;
  if (!(r2 < s_max)) return false;
  // Pure radial: det J = radial * h > 0 below the turning radius, nothing more to check.
  return !tangential || distortJacobianXY(d, x, y).det() > 0.0;
}

ErrorContext cameraContext(const std::string& camera, const std::string& field) {
  ErrorContext c;
  c.camera = camera;
  c.field = field;
  return c;
}

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

}  // namespace

const char* toString(LensModel model) {
  switch (model) {
    case LensModel::kBrownConrady: return "brown-conrady";
    case LensModel::kKannalaBrandt: return "kannala-brandt";
  }
  return "unknown";
}

LensModel lensModelFromString(const std::string& name) {
  for (const char* n : {"brown-conrady", "brown", "brown-conrady-opencv", "radtan", "plumb_bob", "pinhole-radtan"})
    if (name == n) return LensModel::kBrownConrady;
  for (const char* n : {"kannala-brandt", "fisheye", "equidistant", "kb4", "pinhole-equi"})
    if (name == n) return LensModel::kKannalaBrandt;
  throw Error("unknown lens model '" + name +
                  "' (brown-conrady: k1 k2 p1 p2 k3, also brown, radtan, plumb_bob; kannala-brandt: k1..k4 on "
                  "theta, also fisheye, equidistant)",
              fieldContext("model"));
}

void requireBrownConrady(const std::string& camera_name, const Distortion& dist, const std::string& what) {
  if (dist.isBrown()) return;
  throw Error(what + " handles Brown-Conrady lenses only; this camera's lens model is " + toString(dist.model),
              cameraContext(camera_name, "distortion.model"));
}

const char* toString(InverseStatus status) {
  switch (status) {
    case InverseStatus::kConverged: return "converged";
    case InverseStatus::kNotConverged: return "not converged";
    case InverseStatus::kDiverged: return "diverged";
    case InverseStatus::kNotInvertible: return "not invertible";
  }
  return "unknown";
}

const char* toString(InverseMethod method) {
  switch (method) {
    case InverseMethod::kFixedPoint: return "fixed-point";
    case InverseMethod::kNewton: return "newton";
  }
  return "unknown";
}

void InverseOptions::validate() const {
  if (max_iterations < 1)
    throw Error("inverse: max_iterations must be >= 1 (got " + std::to_string(max_iterations) +
                    ")",
                fieldContext("max_iterations"));
  if (!(tolerance > 0.0) || !std::isfinite(tolerance))
    throw Error("inverse: tolerance must be a finite value > 0 (got " + fmt(tolerance) + ")",
                fieldContext("tolerance"));
  if (method != InverseMethod::kFixedPoint && method != InverseMethod::kNewton)
    throw Error("inverse: unknown method", fieldContext("method"));
}

// ---------------------------------------------------------------------------------------------
// InverseDistortion

InverseDistortion::InverseDistortion(const Distortion& dist)
    : dist_(dist), has_tangential_(dist.isBrown() && (dist.p1 != 0.0 || dist.p2 != 0.0)) {
  if (!dist_.isBrown()) {
    // Kannala–Brandt: radial only, |xd| = theta_d, increasing up to kb_max_theta_.
    kb_max_theta_ = kbMaxTheta(dist_);
    s_max_ = kbRadiusSquared(kb_max_theta_);
    r_max_ = std::sqrt(s_max_);
    rd_max_ = lens::kannalaBrandtTheta(dist_.k1, dist_.k2, dist_.k3, dist_.k4, kb_max_theta_);
    return;
  }
  s_max_ = brownTurningRadiusSquared(dist_);
  r_max_ = std::sqrt(s_max_);
  if (std::isfinite(r_max_)) {
    // |distort(x)| <= r radial(r) + |tangential(x)| and, writing x = r (cos a, sin a),
    // tangential(x) = r^2 (2 (p2, p1) + R(2a) (p2, -p1)), so |tangential| <= 3 r^2 |p|. The
    // radial part is increasing on the domain, hence this bound at r_max covers all of it.
    const double radial =
        lens::brownRadial(dist_.k1, dist_.k2, dist_.k3, dist_.k4, dist_.k5, dist_.k6, s_max_);
    const double tangential = 3.0 * s_max_ * std::hypot(dist_.p1, dist_.p2);
    rd_max_ = (r_max_ * radial + tangential) * (1.0 + 1e-12);
    // At a pole of the rational factor the bound is +inf (or NaN from inf * 0).
    if (!(rd_max_ >= 0.0)) rd_max_ = kInf;
  } else {
    rd_max_ = kInf;
  }
}

bool InverseDistortion::inDomain(const Eigen::Vector2d& x) const {
  return inDomainXY(dist_, has_tangential_, s_max_, x.x(), x.y());
}

InverseResult InverseDistortion::solve(const Eigen::Vector2d& xd,
                                       const InverseOptions& options) const {
  InverseResult result;
  if (!std::isfinite(xd.x()) || !std::isfinite(xd.y())) {
    result.point = xd;
    result.status = InverseStatus::kNotInvertible;
    return result;
  }
  if (dist_.isZero()) {
    result.point = xd;
    result.residual = 0.0;
    result.status = InverseStatus::kConverged;
    return result;
  }
  if (!(xd.norm() <= rd_max_)) {
    // Past the image of the turning circle: no ideal point in the domain maps here.
    result.point = xd;
    result.status = InverseStatus::kNotInvertible;
    return result;
  }
  if (!dist_.isBrown()) {
    // One radial equation in theta, solved by safeguarded Newton whatever the method asked
    // (the fixed-point iteration is the thesis' for Brown's model).
    const lens::KannalaBrandtInverse kb = lens::kannalaBrandtUndistort(
        dist_.k1, dist_.k2, dist_.k3, dist_.k4, xd.x(), xd.y(), kb_max_theta_, options.max_iterations,
        std::min(options.tolerance, 1e-14));
    result.point = Eigen::Vector2d(kb.x, kb.y);
    result.iterations = kb.iterations;
    result.status = kb.status;
    if (kb.status == InverseStatus::kNotInvertible) {
      result.point = xd;
      return result;
    }
    const DistortEval e = distortXY(dist_, kb.x, kb.y);
    result.residual = std::hypot(e.xd - xd.x(), e.yd - xd.y());
    if (result.status == InverseStatus::kNotConverged && result.residual <= options.tolerance)
      result.status = InverseStatus::kConverged;
    return result;
  }
  return options.method == InverseMethod::kNewton ? newton(xd, options)
                                                   : fixedPoint(xd, options);
}

InverseResult InverseDistortion::newton(const Eigen::Vector2d& target,
                                        const InverseOptions& options) const {
  const Distortion& d = dist_;
  const double tx = target.x(), ty = target.y();
  double x = tx, y = ty;
  // Start at x = xd; a strong pincushion can put xd itself past the turning radius, in which
  // case the start is pulled towards the centre until it lies in the domain.
  for (int i = 0; i < 64 && !inDomainXY(d, has_tangential_, s_max_, x, y); ++i) {
    x *= 0.5;
    y *= 0.5;
  }
  DistortEval f = distortXY(d, x, y);
  double fx = f.xd - tx, fy = f.yd - ty;
  // Squared residuals inside the loops: hypot() alone would cost as much as the model.
  double res2 = fx * fx + fy * fy;
  const double tol2 = options.tolerance * options.tolerance;

  InverseResult result;
  result.status = InverseStatus::kNotConverged;
  bool domain_limited = false;
  int it = 0;
  for (;;) {
    if (res2 <= tol2) {
      result.status = InverseStatus::kConverged;
      break;
    }
    if (it >= options.max_iterations) {
      // Newton never grows the residual (backtracking); pressing against the fold at the
      // end means the nearest point of the domain is on its boundary: no preimage.
      result.status = domain_limited ? InverseStatus::kNotInvertible : InverseStatus::kNotConverged;
      break;
    }
    const Jacobian J = distortJacobianXY(d, x, y);
    // dx = -J^-1 f (J symmetric, det > 0 inside the domain); one division, it dominates the
    // latency of an iteration.
    const double inv_det = 1.0 / J.det();
    const double dx = (J.xy * fy - J.yy * fx) * inv_det;
    const double dy = (J.xy * fx - J.xx * fy) * inv_det;
    // Backtracking: the step must stay inside the domain (it may not jump across the fold
    // onto another preimage) and must reduce the residual.
    double t = 1.0;
    bool accepted = false;
    domain_limited = false;
    for (int k = 0; k < 60; ++k, t *= 0.5) {
      const double xn = x + t * dx, yn = y + t * dy;
      if (!inDomainXY(d, has_tangential_, s_max_, xn, yn)) {
        domain_limited = true;
        continue;
      }
      const DistortEval fn = distortXY(d, xn, yn);
      const double fxn = fn.xd - tx, fyn = fn.yd - ty;
      const double res2n = fxn * fxn + fyn * fyn;
      if (res2n < res2) {
        x = xn;
        y = yn;
        fx = fxn;
        fy = fyn;
        res2 = res2n;
        accepted = true;
        break;
      }
    }
    if (!accepted) {
      // No step of any length helps: stuck on the boundary of the domain (no preimage), or at
      // the rounding floor above the requested tolerance.
      result.status = domain_limited ? InverseStatus::kNotInvertible : InverseStatus::kNotConverged;
      break;
    }
    ++it;
  }
  result.point = Eigen::Vector2d(x, y);
  result.iterations = it;
  result.residual = std::sqrt(res2);
  return result;
}

InverseResult InverseDistortion::fixedPoint(const Eigen::Vector2d& target,
                                            const InverseOptions& options) const {
  const Distortion& d = dist_;
  const bool rational = d.isRational();  // else the plain model: no division per iteration
  const double tx = target.x(), ty = target.y();
  double x = tx, y = ty;
  InverseResult result;
  result.status = InverseStatus::kNotConverged;
  // Half-way, with the same parity as the last iterate so a 2-cycle compares like with like.
  const int mid = options.max_iterations - 2 * (options.max_iterations / 4);
  // Squared residuals throughout (see newton()).
  double res_mid = kInf;
  double best_before = kInf;  // smallest residual of the earlier iterates
  double res = kInf;
  const double tol2 = options.tolerance * options.tolerance;
  int it = 0;
  // A magnitude no real lens reaches: beyond it the iteration has run away.
  const double runaway = 1e6 * (1.0 + target.norm());
  const double runaway2 = runaway * runaway;
  for (;;) {
    const double r2 = x * x + y * y;
    const double radial = rational ? lens::brownRadial(d.k1, d.k2, d.k3, d.k4, d.k5, d.k6, r2)
                                   : lens::brownRadial<false>(d.k1, d.k2, d.k3, 0.0, 0.0, 0.0, r2);
    double tanx, tany;
    lens::brownTangential(d.p1, d.p2, x, y, tanx, tany);
    // The residual of the current iterate costs nothing extra: it uses the same terms as the
    // update.
    const double ex = x * radial + tanx - tx, ey = y * radial + tany - ty;
    res = ex * ex + ey * ey;
    if (it == mid) res_mid = res;
    if (!std::isfinite(res) || r2 > runaway2) {
      result.status = InverseStatus::kDiverged;
      break;
    }
    if (res <= tol2) {
      // Abeles' iteration can settle on a preimage past the fold: that is not the inverse.
      result.status = inDomainXY(d, has_tangential_, s_max_, x, y) ? InverseStatus::kConverged
                                                                   : InverseStatus::kNotInvertible;
      break;
    }
    if (it >= options.max_iterations) {
      // Slow (linear rate close to 1) when the last iterate is the best so far and the second
      // half gained something real; otherwise it is growing or trapped in a cycle (a
      // pincushion lens far off-axis falls into a stable 2-cycle whose residuals barely move).
      const bool improving = res < best_before && res < res_mid * (1.0 - 2e-3);
      result.status = improving ? InverseStatus::kNotConverged : InverseStatus::kDiverged;
      break;
    }
    best_before = std::min(best_before, res);
    if (!(radial > 0.0)) {  // the update divides by radial: a pole, the iteration has left
      result.status = InverseStatus::kDiverged;
      break;
    }
    x = (tx - tanx) / radial;
    y = (ty - tany) / radial;
    ++it;
  }
  result.point = Eigen::Vector2d(x, y);
  result.iterations = it;
  result.residual = std::sqrt(res);
  return result;
}

// ---------------------------------------------------------------------------------------------
// Camera

void Camera::validate() const {
  auto bad = [&](const std::string& field, const std::string& what) {
    throw Error(what, cameraContext(name, field));
  };
  if (width <= 0) bad("width", "must be > 0 (got " + std::to_string(width) + ")");
  if (height <= 0) bad("height", "must be > 0 (got " + std::to_string(height) + ")");
  if (!(fx > 0.0) || !std::isfinite(fx)) bad("fx", "must be a finite value > 0 (got " + fmt(fx) + ")");
  if (!(fy > 0.0) || !std::isfinite(fy)) bad("fy", "must be a finite value > 0 (got " + fmt(fy) + ")");
  if (!std::isfinite(cx)) bad("cx", "must be finite (got " + fmt(cx) + ")");
  if (!std::isfinite(cy)) bad("cy", "must be finite (got " + fmt(cy) + ")");
  if (!std::isfinite(skew)) bad("skew", "must be finite (got " + fmt(skew) + ")");
  const std::pair<const char*, double> terms[] = {
      {"distortion.k1", dist.k1}, {"distortion.k2", dist.k2}, {"distortion.p1", dist.p1},
      {"distortion.p2", dist.p2}, {"distortion.k3", dist.k3}, {"distortion.k4", dist.k4},
      {"distortion.k5", dist.k5}, {"distortion.k6", dist.k6}};
  for (const auto& [field, v] : terms)
    if (!std::isfinite(v)) bad(field, "must be finite (got " + fmt(v) + ")");
  if (dist.model == LensModel::kKannalaBrandt) {
    if (dist.p1 != 0.0) bad("distortion.p1", "kannala-brandt has k1 k2 k3 k4 only (got p1 " + fmt(dist.p1) + ")");
    if (dist.p2 != 0.0) bad("distortion.p2", "kannala-brandt has k1 k2 k3 k4 only (got p2 " + fmt(dist.p2) + ")");
    if (dist.k5 != 0.0)
      bad("distortion.k5", "kannala-brandt has k1 k2 k3 k4 only; k5 is brown-conrady's rational term (got k5 " +
                               fmt(dist.k5) + ")");
    if (dist.k6 != 0.0)
      bad("distortion.k6", "kannala-brandt has k1 k2 k3 k4 only; k6 is brown-conrady's rational term (got k6 " +
                               fmt(dist.k6) + ")");
  } else if (dist.model != LensModel::kBrownConrady) {
    bad("distortion.model", "unknown lens model");
  }
}

Eigen::Matrix3d Camera::K() const {
  Eigen::Matrix3d K;
  K << fx, skew, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  return K;
}

Eigen::Vector2d Camera::distort(const Eigen::Vector2d& x) const {
  const DistortEval e = distortXY(dist, x.x(), x.y());
  return {e.xd, e.yd};
}

Eigen::Matrix2d Camera::distortJacobian(const Eigen::Vector2d& x) const {
  const Jacobian J = distortJacobianXY(dist, x.x(), x.y());
  Eigen::Matrix2d M;
  M << J.xx, J.xy, J.xy, J.yy;
  return M;
}

InverseResult Camera::undistort(const Eigen::Vector2d& xd, const InverseOptions& options) const {
  if (dist.isZero()) {
    InverseResult r;
    r.point = xd;
    r.residual = 0.0;
    r.status = InverseStatus::kConverged;
    return r;
  }
  return InverseDistortion(dist).solve(xd, options);
}

double Camera::maxInvertibleRadius() const {
  if (!dist.isBrown()) return std::sqrt(kbRadiusSquared(kbMaxTheta(dist)));
  return std::sqrt(brownTurningRadiusSquared(dist));
}

bool Camera::inInvertibleDomain(const Eigen::Vector2d& x) const {
  if (!dist.isBrown()) return x.squaredNorm() < kbRadiusSquared(kbMaxTheta(dist));
  if (!brownIncreasingUpTo(dist, x.squaredNorm())) return false;
  if (dist.p1 == 0.0 && dist.p2 == 0.0) return true;
  return distortJacobianXY(dist, x.x(), x.y()).det() > 0.0;
}

Eigen::Vector2d Camera::normalizedToPixel(const Eigen::Vector2d& xd) const {
  return {fx * xd.x() + skew * xd.y() + cx, fy * xd.y() + cy};
}

Eigen::Vector2d Camera::pixelToNormalized(const Eigen::Vector2d& px) const {
  const double yd = (px.y() - cy) / fy;
  return {(px.x() - cx - skew * yd) / fx, yd};
}

std::optional<Eigen::Vector2d> Camera::project(const Eigen::Vector3d& p_cam) const {
  if (!(p_cam.z() > 0.0)) return std::nullopt;
  const Eigen::Vector2d x(p_cam.x() / p_cam.z(), p_cam.y() / p_cam.z());
  if (!inInvertibleDomain(x)) return std::nullopt;
  return normalizedToPixel(distort(x));
}

std::optional<Eigen::Vector3d> Camera::unproject(const Eigen::Vector2d& px,
                                                 const InverseOptions& options) const {
  const InverseResult r = undistort(pixelToNormalized(px), options);
  if (!r.ok()) return std::nullopt;
  return Eigen::Vector3d(r.point.x(), r.point.y(), 1.0).normalized();
}

bool Camera::inImage(const Eigen::Vector2d& px, double margin) const {
  return px.x() >= -0.5 + margin && px.x() <= width - 0.5 - margin &&
         px.y() >= -0.5 + margin && px.y() <= height - 0.5 - margin;
}

Camera Camera::scaled(double scale_x, double scale_y) const {
  if (!(scale_x > 0.0) || !(scale_y > 0.0))
    throw Error("scale must be > 0 (got " + fmt(scale_x) + ", " + fmt(scale_y) + ")",
                cameraContext(name, "scale"));
  Camera c = *this;
  c.width = static_cast<int>(std::lround(width * scale_x));
  c.height = static_cast<int>(std::lround(height * scale_y));
  c.fx = fx * scale_x;
  c.fy = fy * scale_y;
  c.skew = skew * scale_x;
  c.cx = (cx + 0.5) * scale_x - 0.5;
  c.cy = (cy + 0.5) * scale_y - 0.5;
  return c;
}

}  // namespace previz
