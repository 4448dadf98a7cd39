#pragma once
// The lens models, each defined once (issue 34): the map from ideal normalized coordinates
// (x, y) = (X/Z, Y/Z) to distorted normalized coordinates, its Jacobian, and (lens_model.cpp) its
// inverse with a convergence report. Templates on the scalar: double for the per-point paths,
// float where a per-pixel loop wants it, ceres::Jet for the solvers (only +, -, *, /, sqrt, atan
// and comparisons on the value are used). Every module that projects through a lens calls these;
// none writes the polynomial again.
//
// Brown–Conrady, OpenCV's convention and coefficient order (k1 k2 p1 p2 k3 k4 k5 k6), with
// OpenCV's rational radial factor (CALIB_RATIONAL_MODEL; k4 = k5 = k6 = 0 is the plain model,
// and gives the same numbers to the last bit: the denominator is then exactly 1):
//   r2 = x^2 + y^2, radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
//   xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
//   yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
// Kannala–Brandt equidistant (OpenCV's fisheye module, Kalibr's "equidistant"), k1..k4:
//   r = |(x, y)|, theta = atan(r), theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
//   (xd, yd) = (theta_d / r) (x, y)            ((x, y) itself at r = 0)
// Angles up to 90 degrees off the axis (a 180-degree field of view) are what ideal normalized
// coordinates can carry.
#include <cmath>

namespace previz {

// How an inverse of a lens model ended (Camera::undistort, lens::kannalaBrandtUndistort).
enum class InverseStatus {
  kConverged,      // |distort(x) - xd| <= tolerance
  kNotConverged,   // ran out of iterations while still improving (slow)
  kDiverged,       // the iterate grew without bound or oscillated
  kNotInvertible,  // xd lies outside the image of the invertible domain (past the turning point)
};

namespace lens {

// ---- Brown–Conrady ------------------------------------------------------------------------

// The numerator and denominator of the radial factor and their slopes in r2.
template <typename T>
inline T brownPolynomial(const T& c1, const T& c2, const T& c3, const T& r2) {
  return T(1) + r2 * (c1 + r2 * (c2 + r2 * c3));
}
template <typename T>
inline T brownPolynomialSlope(const T& c1, const T& c2, const T& c3, const T& r2) {
  return c1 + r2 * (T(2) * c2 + r2 * (T(3) * c3));
}

// kRational = false evaluates the plain model (k4 k5 k6 taken as 0, no division): the same numbers
// as kRational = true with k4 = k5 = k6 = 0, 30-40 % faster in Camera's per-point loops. Only for
// a lens whose k4..k6 are 0 and stay 0 (never for Jets that solve them).

// radial(r2) = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
template <bool kRational = true, typename T>
inline T brownRadial(const T& k1, const T& k2, const T& k3, const T& k4, const T& k5, const T& k6,
                     const T& r2) {
  if constexpr (!kRational) return brownPolynomial(k1, k2, k3, r2);
  return brownPolynomial(k1, k2, k3, r2) / brownPolynomial(k4, k5, k6, r2);
}

// The radial factor and d radial / d r2 = (N' - radial D') / D.
template <bool kRational = true, typename T>
inline void brownRadialWithSlope(const T& k1, const T& k2, const T& k3, const T& k4, const T& k5,
                                 const T& k6, const T& r2, T& radial, T& slope) {
  if constexpr (!kRational) {
    radial = brownPolynomial(k1, k2, k3, r2);
    slope = brownPolynomialSlope(k1, k2, k3, r2);
    return;
  }
  const T den = brownPolynomial(k4, k5, k6, r2);
  radial = brownPolynomial(k1, k2, k3, r2) / den;
  slope = (brownPolynomialSlope(k1, k2, k3, r2) - radial * brownPolynomialSlope(k4, k5, k6, r2)) / den;
}

// The tangential (decentring) terms.
template <typename T>
inline void brownTangential(const T& p1, const T& p2, const T& x, const T& y, T& tx, T& ty) {
  const T xy = x * y, r2 = x * x + y * y;
  tx = T(2) * p1 * xy + p2 * (r2 + T(2) * x * x);
  ty = p1 * (r2 + T(2) * y * y) + T(2) * p2 * xy;
}

// Ideal normalized -> distorted normalized.
template <bool kRational = true, typename T>
inline void brownDistort(const T& k1, const T& k2, const T& p1, const T& p2, const T& k3, const T& k4,
                         const T& k5, const T& k6, const T& x, const T& y, T& xd, T& yd) {
  const T radial = brownRadial<kRational>(k1, k2, k3, k4, k5, k6, x * x + y * y);
  T tx, ty;
  brownTangential(p1, p2, x, y, tx, ty);
  xd = x * radial + tx;
  yd = y * radial + ty;
}

// The same and d(xd, yd) / d(x, y) = [j00 j01; j01 j11] (symmetric) in one pass.
template <bool kRational = true, typename T>
inline void brownDistortWithJacobian(const T& k1, const T& k2, const T& p1, const T& p2, const T& k3,
                                     const T& k4, const T& k5, const T& k6, const T& x, const T& y, T& xd,
                                     T& yd, T& j00, T& j01, T& j11) {
  const T x2 = x * x, y2 = y * y, xy = x * y, r2 = x2 + y2;
  T radial, slope;
  brownRadialWithSlope<kRational>(k1, k2, k3, k4, k5, k6, r2, radial, slope);
  T tx, ty;
  brownTangential(p1, p2, x, y, tx, ty);
  xd = x * radial + tx;
  yd = y * radial + ty;
  j00 = radial + T(2) * x2 * slope + T(2) * p1 * y + T(6) * p2 * x;
  j01 = T(2) * xy * slope + T(2) * p1 * x + T(2) * p2 * y;
  j11 = radial + T(2) * y2 * slope + T(6) * p1 * y + T(2) * p2 * x;
}

// d(xd, yd) / d(k1 k2 p1 p2 k3 k4 k5 k6) at the given coefficients (the rational terms make
// the radial ones depend on them): rows xd, yd, row-major 2 x 8, OpenCV's order. With
// k4 = k5 = k6 = 0 the first five columns are the plain model's to the last bit.
template <typename T>
inline void brownCoefficientJacobian(const T& k1, const T& k2, const T& k3, const T& k4, const T& k5,
                                     const T& k6, const T& x, const T& y, T* J) {
  const T r2 = x * x + y * y, r4 = r2 * r2, xy = x * y;
  const T den = brownPolynomial(k4, k5, k6, r2);
  const T radial = brownPolynomial(k1, k2, k3, r2) / den;
  // d radial / d k1..k3 = r2^i / D; d radial / d k4..k6 = -radial r2^i / D. (r4 / D) r2, not
  // r6 / D: the plain model's (x r4) r2, rounded as before.
  const T n1 = r2 / den, n2 = r4 / den, n3 = n2 * r2;
  const T d1 = -radial * n1, d2 = -radial * n2, d3 = -radial * n3;
  J[0] = x * n1;
  J[1] = x * n2;
  J[2] = T(2) * xy;
  J[3] = r2 + T(2) * x * x;
  J[4] = x * n2 * r2;
  J[5] = x * d1;
  J[6] = x * d2;
  J[7] = x * d3;
  J[8] = y * n1;
  J[9] = y * n2;
  J[10] = r2 + T(2) * y * y;
  J[11] = T(2) * xy;
  J[12] = y * n2 * r2;
  J[13] = y * d1;
  J[14] = y * d2;
  J[15] = y * d3;
}

// ---- Kannala–Brandt (equidistant) --------------------------------------------------------

// theta_d(theta) = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
template <typename T>
inline T kannalaBrandtTheta(const T& k1, const T& k2, const T& k3, const T& k4, const T& theta) {
  const T t2 = theta * theta;
  return theta * (T(1) + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))));
}

// d theta_d / d theta
template <typename T>
inline T kannalaBrandtThetaSlope(const T& k1, const T& k2, const T& k3, const T& k4, const T& theta) {
  const T t2 = theta * theta;
  return T(1) + t2 * (T(3) * k1 + t2 * (T(5) * k2 + t2 * (T(7) * k3 + t2 * (T(9) * k4))));
}

// Ideal normalized -> distorted normalized. Below r = 1e-8 the map is the identity to 1e-16.
template <typename T>
inline void kannalaBrandtDistort(const T& k1, const T& k2, const T& k3, const T& k4, const T& x, const T& y,
                                 T& xd, T& yd) {
  using std::atan;
  using std::sqrt;
  const T r2 = x * x + y * y;
  if (!(r2 > T(1e-16))) {
    xd = x;
    yd = y;
    return;
  }
  const T r = sqrt(r2);
  const T scale = kannalaBrandtTheta(k1, k2, k3, k4, atan(r)) / r;
  xd = x * scale;
  yd = y * scale;
}

// The same and d(xd, yd) / d(x, y) = [j00 j01; j01 j11] (symmetric).
template <typename T>
inline void kannalaBrandtDistortWithJacobian(const T& k1, const T& k2, const T& k3, const T& k4, const T& x,
                                             const T& y, T& xd, T& yd, T& j00, T& j01, T& j11) {
  using std::atan;
  using std::sqrt;
  const T r2 = x * x + y * y;
  if (!(r2 > T(1e-16))) {
    xd = x;
    yd = y;
    j00 = j11 = T(1);
    j01 = T(0);
    return;
  }
  const T r = sqrt(r2);
  const T theta = atan(r);
  const T s = kannalaBrandtTheta(k1, k2, k3, k4, theta) / r;  // xd = s x
  // ds/dr = (theta_d'(theta) / (1 + r^2) - s) / r; d s / d x = ds/dr x / r
  const T ds_dr = (kannalaBrandtThetaSlope(k1, k2, k3, k4, theta) / (T(1) + r2) - s) / r;
  const T g = ds_dr / r;
  xd = x * s;
  yd = y * s;
  j00 = s + g * x * x;
  j01 = g * x * y;
  j11 = s + g * y * y;
}

// d(xd, yd) / d(k1 k2 k3 k4): rows xd, yd, row-major 2 x 4.
template <typename T>
inline void kannalaBrandtCoefficientJacobian(const T& x, const T& y, T* J) {
  using std::atan;
  using std::sqrt;
  const T r2 = x * x + y * y;
  if (!(r2 > T(1e-16))) {
    for (int i = 0; i < 8; ++i) J[i] = T(0);
    return;
  }
  const T r = sqrt(r2);
  const T theta = atan(r), t2 = theta * theta;
  T power = theta * t2;  // theta^3, ^5, ^7, ^9
  for (int i = 0; i < 4; ++i) {
    J[i] = x * power / r;
    J[4 + i] = y * power / r;
    power *= t2;
  }
}

// ---- Inverses ------------------------------------------------------------------------------

// Kannala–Brandt's inverse: theta from theta_d = |(xd, yd)| by Newton on the monotonic part of
// theta_d(theta) (theta in [0, min(turning angle, 90 degrees))), then (x, y) = tan(theta) / theta_d
// (xd, yd). max_theta: where theta_d stops increasing or pi/2, whichever is first
// (kannalaBrandtMaxTheta). Reports as Camera::undistort does.
struct KannalaBrandtInverse {
  double x = 0, y = 0;  // ideal normalized
  int iterations = 0;
  double residual = 0;  // |theta_d(theta) - |xd|| (radians)
  InverseStatus status = InverseStatus::kNotConverged;
};
double kannalaBrandtMaxTheta(double k1, double k2, double k3, double k4);
KannalaBrandtInverse kannalaBrandtUndistort(double k1, double k2, double k3, double k4, double xd, double yd,
                                            double max_theta, int max_iterations = 50, double tolerance = 1e-14);

}  // namespace lens
}  // namespace previz
