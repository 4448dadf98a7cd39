// Inverse distortion: Newton's round trip over a grid of lenses, the fold (not invertible), and
// where the thesis' fixed-point iteration (Abeles) is slow or fails (cf. its appendix A images).
#include <cmath>
#include <filesystem>
#include <iostream>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/io.h"
#include "scratch.h"

namespace previz {
namespace {

constexpr double kPi = 3.14159265358979323846;

Camera lensCamera(const Distortion& d, double f = 900) {
  Camera cam;
  cam.name = "lens";
  cam.width = 1280;
  cam.height = 720;
  cam.fx = cam.fy = f;
  cam.cx = 639.5;
  cam.cy = 359.5;
  cam.dist = d;
  return cam;
}

// k1 in [-0.5, 1.0], k2 in [-0.3, 0.3], tangential up to +-0.01.
std::vector<Distortion> lensGrid() {
  std::vector<Distortion> out;
  for (double k1 : {-0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0})
    for (double k2 : {-0.3, -0.15, 0.0, 0.15, 0.3})
      for (auto [p1, p2] : {std::pair{0.0, 0.0}, {0.01, 0.0}, {0.0, -0.01}, {0.01, 0.01}, {-0.01, 0.01}})
        out.push_back({k1, k2, p1, p2, 0.0});
  return out;
}

// Every 32nd column / 30th row plus the last ones: corners and edges included.
std::vector<Eigen::Vector2d> pixelGrid(const Camera& cam) {
  std::vector<Eigen::Vector2d> px;
  for (int v = 0;; v += 30) {
    v = std::min(v, cam.height - 1);
    for (int u = 0;; u += 32) {
      u = std::min(u, cam.width - 1);
      px.emplace_back(u, v);
      if (u == cam.width - 1) break;
    }
    if (v == cam.height - 1) break;
  }
  return px;
}

std::string describe(const Distortion& d) {
  std::ostringstream s;
  s << "k1=" << d.k1 << " k2=" << d.k2 << " p1=" << d.p1 << " p2=" << d.p2;
  return s.str();
}

double radialImage(const Distortion& d, double r) {
  const double s = r * r;
  return r * (1 + s * (d.k1 + s * (d.k2 + s * d.k3)));
}

// Every grid pixel either comes back through project() within 1e-6 px, or is reported not
// invertible. For purely radial lenses the image of the domain is exactly the open disc of
// radius g(r_max), which decides which of the two must happen.
TEST(InverseDistortion, NewtonRoundTripBelowOneMicroPixelWhereverInvertible) {
  double max_err = 0;
  long converged = 0, not_invertible = 0, total = 0;
  int max_iterations = 0;
  for (const Distortion& d : lensGrid()) {
    const Camera cam = lensCamera(d);
    const double rmax = cam.maxInvertibleRadius();
    const double rd_edge = std::isfinite(rmax) ? radialImage(d, rmax) : INFINITY;
    const bool radial_only = d.p1 == 0 && d.p2 == 0;
    for (const Eigen::Vector2d& px : pixelGrid(cam)) {
      ++total;
      const Eigen::Vector2d xd = cam.pixelToNormalized(px);
      const InverseResult r = cam.undistort(xd);
      if (r.ok()) {
        ++converged;
        max_iterations = std::max(max_iterations, r.iterations);
        ASSERT_TRUE(cam.inInvertibleDomain(r.point)) << describe(d) << " px " << px.transpose();
        const auto back = cam.project(Eigen::Vector3d(r.point.x(), r.point.y(), 1.0));
        ASSERT_TRUE(back.has_value());
        const double err = (*back - px).norm();
        max_err = std::max(max_err, err);
        ASSERT_LE(err, 1e-6) << describe(d) << " px " << px.transpose();
        ASSERT_NEAR(r.residual, (cam.distort(r.point) - xd).norm(), 1e-16);
        if (radial_only) {
          ASSERT_LT(xd.norm(), rd_edge) << describe(d);
        }
      } else {
        ++not_invertible;
        ASSERT_EQ(r.status, InverseStatus::kNotInvertible)
            << describe(d) << " px " << px.transpose() << " status " << toString(r.status);
        if (radial_only) {
          ASSERT_GE(xd.norm(), rd_edge * (1 - 1e-12)) << describe(d) << " px " << px.transpose();
        }
      }
    }
  }
  std::cout << lensGrid().size() << " lenses x " << total / lensGrid().size() << " pixels: " << converged
            << " converged (max round trip " << max_err << " px, max " << max_iterations
            << " iterations), " << not_invertible << " not invertible\n";
  EXPECT_GT(not_invertible, 0);  // the strong barrel lenses fold inside the 1280x720 frame
  EXPECT_GT(converged, total / 2);
}

// Sampling the domain itself: every ideal point below the turning radius (and with det J > 0)
// is recovered, with the tangential lenses included.
TEST(InverseDistortion, NewtonRecoversEveryIdealPointOfTheDomain) {
  double max_px = 0, max_x = 0;
  long n = 0;
  for (const Distortion& d : lensGrid()) {
    const Camera cam = lensCamera(d);
    const double rlim = std::min(cam.maxInvertibleRadius() * (1 - 1e-6), 1.5);
    for (int i = 1; i <= 60; ++i) {
      // Denser towards the rim, where the fold makes the inverse hardest.
      const double r = rlim * (1 - std::pow(1 - i / 60.0, 2));
      for (int a = 0; a < 48; ++a) {
        const Eigen::Vector2d x(r * std::cos(2 * kPi * a / 48), r * std::sin(2 * kPi * a / 48));
        if (!cam.inInvertibleDomain(x)) continue;
        const Eigen::Vector2d px = cam.normalizedToPixel(cam.distort(x));
        const InverseResult res = cam.undistort(cam.pixelToNormalized(px));
        ASSERT_TRUE(res.ok()) << describe(d) << " x " << x.transpose() << ": " << toString(res.status);
        max_px = std::max(max_px, (cam.normalizedToPixel(cam.distort(res.point)) - px).norm());
        max_x = std::max(max_x, (res.point - x).norm());
        ++n;
      }
    }
  }
  std::cout << n << " ideal points: max reprojection " << max_px << " px, max ideal error " << max_x << "\n";
  EXPECT_LE(max_px, 1e-6);
  EXPECT_LE(max_x, 1e-6);  // ill-conditioned only within 1e-6 of the fold
}

// A point past the turning radius shares its image with a point inside (the fold). Its pixel
// must come back either as kNotInvertible or as that in-domain twin (which reprojects onto
// the same pixel) — never as a converged point that is outside the domain or misses the pixel.
TEST(InverseDistortion, FoldedPointsAreNeverSilentlyMisinverted) {
  long twins = 0, refused = 0, fp_refused = 0;
  for (const Distortion& d : lensGrid()) {
    const Camera cam = lensCamera(d);
    const double rmax = cam.maxInvertibleRadius();
    if (!std::isfinite(rmax)) continue;
    const bool radial_only = d.p1 == 0 && d.p2 == 0;
    const double rd_edge = radialImage(d, rmax);
    for (int i = 1; i <= 40; ++i) {
      const double r = rmax * (1 + 1.5 * i / 40.0);
      for (int a = 0; a < 24; ++a) {
        const Eigen::Vector2d x(r * std::cos(2 * kPi * (a + 0.5) / 24), r * std::sin(2 * kPi * (a + 0.5) / 24));
        ASSERT_FALSE(cam.inInvertibleDomain(x));
        ASSERT_FALSE(cam.project(Eigen::Vector3d(x.x(), x.y(), 1)).has_value());
        const Eigen::Vector2d xd = cam.distort(x);
        if (!xd.allFinite() || xd.norm() > 1e6) continue;
        const Eigen::Vector2d px = cam.normalizedToPixel(xd);
        for (InverseMethod m : {InverseMethod::kNewton, InverseMethod::kFixedPoint}) {
          InverseOptions o;
          o.method = m;
          const InverseResult res = cam.undistort(cam.pixelToNormalized(px), o);
          if (res.ok()) {
            ASSERT_TRUE(cam.inInvertibleDomain(res.point)) << describe(d) << " " << toString(m);
            ASSERT_LE((cam.normalizedToPixel(cam.distort(res.point)) - px).norm(), 1e-6);
            ASSERT_GT((res.point - x).norm(), 1e-3);  // the twin, not the folded point
            if (m == InverseMethod::kNewton) ++twins;
          } else if (m == InverseMethod::kNewton) {
            ASSERT_EQ(res.status, InverseStatus::kNotInvertible) << describe(d) << " " << toString(res.status);
            ++refused;
          } else if (res.status == InverseStatus::kNotInvertible) {
            ++fp_refused;
          }
          // Purely radial: a twin exists exactly when the distorted radius is below g(r_max).
          if (radial_only && m == InverseMethod::kNewton) {
            ASSERT_EQ(res.ok(), xd.norm() < rd_edge) << describe(d) << " r " << r;
          }
        }
      }
    }
  }
  std::cout << "folded points: Newton found the in-domain twin for " << twins << ", reported "
            << refused << " not invertible; fixed point reported " << fp_refused << " not invertible\n";
  EXPECT_GT(twins, 0);
  EXPECT_GT(refused, 0);
}

struct MethodStats {
  long pixels = 0, invertible = 0, fp_failed = 0, fp_diverged = 0;
  double newton_iterations = 0, fp_iterations = 0;              // over pixels both converged on
  double newton_iterations_rim = 0, fp_iterations_rim = 0;      // same, ideal radius > 0.9 r_max
  long both = 0, both_rim = 0;
  double min_failed_radius = INFINITY;                          // ideal radius / r_max
  int newton_max = 0;
};

// Whole 1280x720 image, every 4th pixel; fixed point with the default 100 iterations.
MethodStats compareMethods(const Camera& cam, cv::Mat* fp_iterations_image = nullptr) {
  const InverseDistortion inverse(cam.dist);
  const double rmax = inverse.maxInvertibleRadius();
  InverseOptions fp;
  fp.method = InverseMethod::kFixedPoint;
  MethodStats s;
  if (fp_iterations_image) *fp_iterations_image = cv::Mat(cam.height / 4, cam.width / 4, CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < cam.height; v += 4) {
    for (int u = 0; u < cam.width; u += 4) {
      ++s.pixels;
      const Eigen::Vector2d xd = cam.pixelToNormalized({u, v});
      const InverseResult n = inverse.solve(xd);
      const InverseResult f = inverse.solve(xd, fp);
      // 0: no preimage (outside the folded disc), 2 x iterations, 255: fixed point failed.
      if (fp_iterations_image)
        fp_iterations_image->at<uint8_t>(v / 4, u / 4) =
            !n.ok() ? 0 : f.ok() ? static_cast<uint8_t>(std::min(254, 2 * f.iterations)) : 255;
      if (!n.ok()) {
        EXPECT_FALSE(f.ok());  // no preimage for Newton means none for fixed point either
        continue;
      }
      ++s.invertible;
      s.newton_max = std::max(s.newton_max, n.iterations);
      const double rel = n.point.norm() / rmax;
      if (!f.ok()) {
        ++s.fp_failed;
        if (f.status == InverseStatus::kDiverged) ++s.fp_diverged;
        s.min_failed_radius = std::min(s.min_failed_radius, rel);
        continue;
      }
      EXPECT_LE((f.point - n.point).norm(), 1e-9);  // when both converge they agree
      ++s.both;
      s.newton_iterations += n.iterations;
      s.fp_iterations += f.iterations;
      if (rel > 0.9) {
        ++s.both_rim;
        s.newton_iterations_rim += n.iterations;
        s.fp_iterations_rim += f.iterations;
      }
    }
  }
  std::cout << describe(cam.dist) << " f=" << cam.fx << ": " << s.invertible << "/" << s.pixels
            << " invertible; fixed point failed on " << s.fp_failed << " ("
            << 100.0 * s.fp_failed / std::max(1L, s.invertible) << " %, " << s.fp_diverged
            << " diverged), first failure at r/r_max = "
            << (std::isfinite(rmax) ? std::to_string(s.min_failed_radius) : std::string("- (no fold)"))
            << "; mean iterations fixed point " << s.fp_iterations / std::max(1L, s.both) << " vs Newton "
            << s.newton_iterations / std::max(1L, s.both) << " (rim r > 0.9 r_max: "
            << s.fp_iterations_rim / std::max(1L, s.both_rim) << " vs "
            << s.newton_iterations_rim / std::max(1L, s.both_rim) << "), Newton max " << s.newton_max << "\n";
  return s;
}

// Strong barrel: near the fold the fixed-point map's slope r |radial'| / radial tends to 1, so
// it crawls and then stops short within 100 iterations; Newton does not care.
TEST(InverseDistortion, FixedPointStallsNearTheFoldOfAStrongBarrelLens) {
  cv::Mat iterations;
  const MethodStats s = compareMethods(lensCamera({-0.5, 0, 0, 0, 0}), &iterations);
  const std::filesystem::path out = test::scratchDir("inverse_distortion", "pictures") / "fixed_point_iterations_k1_-0.5.png";
  writeImageAtomic(out, iterations);  // the thesis' appendix A picture, for a person to look at
  EXPECT_GT(s.fp_failed, 0);
  EXPECT_EQ(s.fp_diverged, 0);                // it is slow, not unstable: all failures are kNotConverged
  EXPECT_GT(s.min_failed_radius, 0.9);        // failures only in the ring next to the fold
  EXPECT_LT(s.fp_failed, s.invertible / 20);  // ... which is a thin ring
  EXPECT_GT(s.fp_iterations_rim / s.both_rim, 5 * s.newton_iterations_rim / s.both_rim);
  EXPECT_GT(s.fp_iterations / s.both, 3 * s.newton_iterations / s.both);
  EXPECT_LE(s.newton_max, 15);
}

// Strong pincushion: at f = 900 px the fixed point still converges everywhere but needs several
// times Newton's iterations; with a wider lens (f = 450 px) its slope passes -1 off-axis and it
// falls into a 2-cycle (kDiverged) where Newton converges on every pixel.
TEST(InverseDistortion, FixedPointOscillatesForAWideStrongPincushionLens) {
  const MethodStats normal = compareMethods(lensCamera({1.0, 0, 0, 0, 0}));
  EXPECT_EQ(normal.invertible, normal.pixels);
  EXPECT_EQ(normal.fp_failed, 0);
  EXPECT_GT(normal.fp_iterations / normal.both, 4 * normal.newton_iterations / normal.both);

  const MethodStats wide = compareMethods(lensCamera({1.0, 0.3, 0, 0, 0}, 450));
  EXPECT_EQ(wide.invertible, wide.pixels);
  EXPECT_GT(wide.fp_diverged, wide.pixels / 20);
  EXPECT_LE(wide.newton_max, 15);
}

}  // namespace
}  // namespace previz
