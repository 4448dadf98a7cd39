#pragma once
// Pinhole camera with a lens model (core/lens_model.h, where each model is defined once):
// Brown–Conrady in OpenCV's convention, or Kannala–Brandt equidistant (OpenCV's fisheye module,
// Kalibr's "equidistant"). The model distorts ideal normalized coordinates (x, y) = (X/Z, Y/Z) to
// (xd, yd), then
//   u = fx xd + skew yd + cx,  v = fy yd + cy
// Pixel (0,0) is the centre of the top-left pixel; camera frame x right, y down, z forward.
// See docs/conventions.md.
#include <Eigen/Core>
#include <limits>
#include <optional>
#include <string>

#include "core/lens_model.h"

namespace previz {

enum class LensModel {
  kBrownConrady,   // k1 k2 p1 p2 k3 [k4 k5 k6] (OpenCV's order; k4..k6 the rational terms, 0 when unused)
  kKannalaBrandt,  // k1 k2 k3 k4 on theta (OpenCV fisheye's D); p1, p2, k5, k6 must be 0
};
// "brown-conrady" / "kannala-brandt" (the names rig.json, reports and --model use).
const char* toString(LensModel model);
// Also accepts the other tools' names: brown, radtan, plumb_bob, pinhole-radtan; fisheye,
// equidistant, kb4. Throws Error naming the value.
LensModel lensModelFromString(const std::string& name);

// {k1, k2, p1, p2, k3} is a Brown–Conrady lens and {k1, k2, p1, p2, k3, k4, k5, k6} one with
// OpenCV's rational terms: the order of OpenCV's D (the model comes last so that D's order
// initialises it); Distortion::kannalaBrandt(k1, k2, k3, k4) a fisheye. k4 is the rational
// denominator's first term for Brown–Conrady and theta^9's coefficient for Kannala–Brandt.
struct Distortion {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0, k4 = 0, k5 = 0, k6 = 0;
  LensModel model = LensModel::kBrownConrady;
  static Distortion kannalaBrandt(double k1, double k2, double k3, double k4) {
    Distortion d;
    d.k1 = k1;
    d.k2 = k2;
    d.k3 = k3;
    d.k4 = k4;
    d.model = LensModel::kKannalaBrandt;
    return d;
  }
  // The identity map (a Kannala–Brandt lens with zero coefficients is not: it is equidistant).
  bool isZero() const {
    return model == LensModel::kBrownConrady && k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0 && k4 == 0 &&
           k5 == 0 && k6 == 0;
  }
  bool isBrown() const { return model == LensModel::kBrownConrady; }
  // A Brown–Conrady lens with a rational denominator (any of k4 k5 k6 non-zero).
  bool isRational() const { return isBrown() && (k4 != 0 || k5 != 0 || k6 != 0); }
  bool operator==(const Distortion& o) const {
    return model == o.model && k1 == o.k1 && k2 == o.k2 && p1 == o.p1 && p2 == o.p2 && k3 == o.k3 && k4 == o.k4 &&
           k5 == o.k5 && k6 == o.k6;
  }
  bool operator!=(const Distortion& o) const { return !(*this == o); }
};

// Throws Error naming the camera when its lens model is not Brown–Conrady: for code paths that
// do not carry the other models yet. 'what' says which (e.g. "the lens table").
void requireBrownConrady(const std::string& camera_name, const Distortion& dist, const std::string& what);

// Inverse of the distortion (distorted normalized -> ideal normalized).
enum class InverseMethod {
  kFixedPoint,  // the thesis' iteration (Abeles): x <- (xd - tangential(x)) / radial(x)
  kNewton,      // Gauss–Newton on the 2x2 Jacobian of distort(), started at x = xd
};

const char* toString(InverseStatus status);
const char* toString(InverseMethod method);

struct InverseOptions {
  InverseMethod method = InverseMethod::kNewton;
  int max_iterations = 100;
  double tolerance = 1e-13;  // on |distort(x) - xd| in normalized units
  void validate() const;     // throws Error naming the field
};

struct InverseResult {
  Eigen::Vector2d point = Eigen::Vector2d::Zero();  // ideal normalized coordinates
  int iterations = 0;
  double residual = std::numeric_limits<double>::infinity();  // |distort(point) - xd|
  InverseStatus status = InverseStatus::kNotConverged;
  bool ok() const { return status == InverseStatus::kConverged; }
};

// The inverse of one lens's distortion with its invertible domain worked out once (turning
// radius, bound on the image of the domain). Camera::undistort builds one per call; loops over
// many points (maps, benchmarks) build one and reuse it. Cheap to copy, immutable, thread-safe.
class InverseDistortion {
 public:
  explicit InverseDistortion(const Distortion& dist);
  InverseResult solve(const Eigen::Vector2d& xd, const InverseOptions& options = {}) const;
  // See Camera::maxInvertibleRadius().
  double maxInvertibleRadius() const { return r_max_; }
  // True when the ideal point x lies in the invertible domain: |x| below the turning radius
  // and, with tangential terms, det(d distort / d x) > 0.
  bool inDomain(const Eigen::Vector2d& x) const;
  // Distorted points farther than this from the centre have no preimage in the domain
  // (+inf when the radial map never turns).
  double maxDistortedRadius() const { return rd_max_; }

 private:
  InverseResult newton(const Eigen::Vector2d& xd, const InverseOptions& options) const;
  InverseResult fixedPoint(const Eigen::Vector2d& xd, const InverseOptions& options) const;
  Distortion dist_;
  bool has_tangential_ = false;
  double kb_max_theta_ = 0;  // Kannala–Brandt: where theta_d stops increasing (<= pi/2)
  double s_max_;   // squared turning radius
  double r_max_;
  double rd_max_;
};

class Camera {
 public:
  std::string name;
  int width = 0;
  int height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0, skew = 0;
  Distortion dist;

  // Throws previz::Error naming the camera and the bad field.
  void validate() const;

  Eigen::Matrix3d K() const;

  // Ideal normalized -> distorted normalized (the lens model of core/lens_model.h).
  Eigen::Vector2d distort(const Eigen::Vector2d& x) const;
  // d distort / d x (2x2).
  Eigen::Matrix2d distortJacobian(const Eigen::Vector2d& x) const;
  // Distorted normalized -> ideal normalized, with a convergence report.
  InverseResult undistort(const Eigen::Vector2d& xd, const InverseOptions& options = {}) const;

  // Radius (ideal normalized) at which the radial map (Brown: r -> r radial(r^2), radial the
  // rational factor of lens_model.h, which ends the domain also at a zero of its denominator;
  // Kannala–Brandt: tan of the angle where theta_d stops increasing, or of 90 degrees) stops
  // increasing; +inf when it never does. Points past it fold back onto the image and
  // are reported as not invertible / not projectable.
  double maxInvertibleRadius() const;
  // True when the ideal normalized point lies in the invertible domain (see InverseDistortion).
  bool inInvertibleDomain(const Eigen::Vector2d& x) const;

  // Normalized (distorted) <-> pixel through K (skew included).
  Eigen::Vector2d normalizedToPixel(const Eigen::Vector2d& xd) const;
  Eigen::Vector2d pixelToNormalized(const Eigen::Vector2d& px) const;

  // 3-D point in the camera frame -> pixel. nullopt when z <= 0 or when the point lies past
  // the invertible radius. Does not clip to the image (use inImage()).
  std::optional<Eigen::Vector2d> project(const Eigen::Vector3d& p_cam) const;
  // Pixel -> unit ray in the camera frame (z > 0). nullopt when the pixel is not invertible.
  std::optional<Eigen::Vector3d> unproject(const Eigen::Vector2d& px,
                                           const InverseOptions& options = {}) const;

  // True when the pixel centre lies within [-0.5 + margin, width - 0.5 - margin] (same in y).
  bool inImage(const Eigen::Vector2d& px, double margin = 0) const;

  // The same camera at another resolution (intrinsics scaled about the pixel-centre
  // convention: c' = (c + 0.5) s - 0.5).
  Camera scaled(double scale_x, double scale_y) const;
};

}  // namespace previz
