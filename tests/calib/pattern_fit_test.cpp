// The model-based corner fit (calib/detail/pattern_fit.h) on patches rendered the way the
// studio renders (supersampled sharp print in linear light, Gaussian defocus, sRGB, 8 bits):
// the exact bivariate normal it rests on, its accuracy against the known corner, its noise
// against its own covariance, and the lens-bend correction.
#include "calib/detail/pattern_fit.h"

#include <cmath>
#include <cstdio>
#include <functional>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "datasets/render.h"

namespace previz::calib::detail {
namespace {

// P(X < h, Y < k) by brute force: integrate phi(x) Phi((k - r x) / sqrt(1 - r^2)) over x < h.
double bruteForceBvn(double h, double k, double r) {
  const double lo = -12.0, hi = std::min(h, 12.0);
  if (hi <= lo) return 0;
  const int n = 200000;
  const double dx = (hi - lo) / n;
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double x = lo + (i + 0.5) * dx;
    sum += std::exp(-0.5 * x * x) / std::sqrt(2 * M_PI) * 0.5 *
           std::erfc(-(k - r * x) / std::sqrt(2 * (1 - r * r)));
  }
  return sum * dx;
}

TEST(DetectPatternFit, BivariateNormalMatchesNumericalIntegration) {
  for (double r : {0.0, 0.2, -0.45, 0.7, -0.9}) {
    for (double h : {-2.5, -0.3, 0.0, 0.8, 3.0}) {
      for (double k : {-1.7, 0.0, 0.4, 2.2}) {
        const double exact = bruteForceBvn(h, k, r);
        EXPECT_NEAR(bivariateNormalCdf(h, k, r), exact, 1e-9) << h << " " << k << " " << r;
      }
    }
  }
  EXPECT_NEAR(bivariateNormalCdf(0.3, -0.2, 0.0), 0.5 * std::erfc(-0.3 / std::sqrt(2.0)) * 0.5 *
                                                       std::erfc(0.2 / std::sqrt(2.0)),
              1e-15);
  EXPECT_TRUE(std::isnan(bivariateNormalCdf(0, 0, 0.95)));  // not needed: not fitted
}

// A board seen in perspective: 40 mm squares at ~0.6 px/mm, tilted 40 degrees, turned 20; the
// point (board origin) lands at `at` in a size x size patch. Optionally bent by a radial lens
// term about `lens_centre` (q -> c + (q - c)(1 + k |q - c|^2)).
struct Scene {
  Eigen::Matrix3d H;  // board metres -> px (before the bend)
  Eigen::Vector2d lens_centre = Eigen::Vector2d::Zero();
  double k = 0;
  Eigen::Vector2d bend(const Eigen::Vector2d& q) const {
    return lens_centre + (q - lens_centre) * (1 + k * (q - lens_centre).squaredNorm());
  }
  Eigen::Vector2d project(const Eigen::Vector2d& b) const {
    return bend((H * b.homogeneous()).hnormalized());
  }
};

Scene perspectiveScene(const Eigen::Vector2d& at, double tilt_deg = 40, double distance_m = 1.3) {
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(20 * M_PI / 180, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(tilt_deg * M_PI / 180, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  Eigen::Matrix3d K;
  K << 800, 0, at.x(), 0, 800, at.y(), 0, 0, 1;
  Eigen::Matrix3d Rt;
  Rt << R.col(0), R.col(1), Eigen::Vector3d(0, 0, distance_m);
  Scene s;
  s.H = K * Rt;
  s.H /= s.H(2, 2);
  return s;
}

// Renders like datasets/render.h: sub-pixel samples of the sharp print (8 x 8 a pixel, linear
// light: paper 0.8, ink 0.03), Gaussian defocus; then encodeGrey: sRGB, noise in grey levels, 8
// bits. The bend is applied by inverting it per sample (fixed-point steps).
cv::Mat linearPatch(const Scene& scene, int size, const std::function<bool(Eigen::Vector2d)>& black,
                    double blur_px) {
  constexpr int kUp = 8;
  const Eigen::Matrix3d H_inv = scene.H.inverse();
  cv::Mat fine(size * kUp, size * kUp, CV_32F);
  for (int v = 0; v < fine.rows; ++v)
    for (int u = 0; u < fine.cols; ++u) {
      const Eigen::Vector2d q((u + 0.5) / kUp - 0.5, (v + 0.5) / kUp - 0.5);
      Eigen::Vector2d straight = q;  // invert the bend: bend(straight) = q
      if (scene.k != 0)
        for (int it = 0; it < 60; ++it) straight += q - scene.bend(straight);
      const Eigen::Vector2d b = (H_inv * straight.homogeneous()).hnormalized();
      fine.at<float>(v, u) = black(b) ? 0.03f : 0.8f;
    }
  if (blur_px > 0) cv::GaussianBlur(fine, fine, cv::Size(0, 0), blur_px * kUp);
  cv::Mat linear;
  cv::resize(fine, linear, cv::Size(size, size), 0, 0, cv::INTER_AREA);
  return linear;
}

cv::Mat encodeGrey(const cv::Mat& linear, double noise, std::uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat grey(linear.size(), CV_8U);
  for (int v = 0; v < linear.rows; ++v)
    for (int u = 0; u < linear.cols; ++u) {
      const double g = 255 * synth::srgbEncode(linear.at<float>(v, u)) + rng.gaussian(noise);
      grey.at<std::uint8_t>(v, u) = cv::saturate_cast<std::uint8_t>(g);
    }
  return grey;
}

cv::Mat renderPatch(const Scene& scene, int size, const std::function<bool(Eigen::Vector2d)>& black,
                    double blur_px) {
  return encodeGrey(linearPatch(scene, size, black, blur_px), 0.0, 1);
}

constexpr double kSquare = 0.04;
bool chessboardBlack(const Eigen::Vector2d& b) {
  const int c = static_cast<int>(std::floor(b.x() / kSquare));
  const int r = static_cast<int>(std::floor(b.y() / kSquare));
  return (c + r) % 2 == 0;
}
LocalPattern chessboardPattern() {
  // Squares (0, 0) and (1, 1) around inner corner (0, 0) are black, as in chessboardBlack.
  return chessboardCornerPattern(kSquare, 0, 0, [](int r, int c) { return (r + c) % 2 == 0; });
}

// The homography moved so that H(0) = start (the fit's starting point).
Eigen::Matrix3d startingAt(const Eigen::Matrix3d& H, const Eigen::Vector2d& start) {
  Eigen::Matrix3d T = Eigen::Matrix3d::Identity();
  T.block<2, 1>(0, 2) = start - (H * Eigen::Vector3d(0, 0, 1)).hnormalized();
  return T * H;
}

// Noise-free, from 0.4 px off: the fit lands on the corner to a few thousandths of a pixel
// (what is left is the 8 x 8 supersampling and the 8-bit rounding), at sub-pixel positions
// all over the pixel.
TEST(DetectPatternFit, ChessboardCornerFoundToThousandthsOfAPixel) {
  double worst = 0;
  for (double dx : {0.0, 0.27, 0.5, 0.81}) {
    const Eigen::Vector2d at(20 + dx, 20 + 0.37 * dx);
    const Scene scene = perspectiveScene(at);
    const cv::Mat grey = renderPatch(scene, 41, chessboardBlack, 1.0);
    const PatternFit fit = fitLocalPattern(
        grey, startingAt(scene.H, at + Eigen::Vector2d(0.3, -0.25)), chessboardPattern());
    ASSERT_TRUE(fit.ok) << fit.why;
    worst = std::max(worst, (fit.px - at).norm());
    // The blur it fitted: 1 px defocus and the pixel's box (1/12 px^2).
    EXPECT_NEAR(fit.blur_sigma_px, std::sqrt(1.0 + 1.0 / 12), 0.05);
  }
  std::printf("  chessboard corner, noise-free: worst error %.4f px\n", worst);
  EXPECT_LT(worst, 0.005);
}

// Noise 2 grey levels, 200 draws: no bias beyond its standard error, and the spread is the one
// the fit's covariance reports (within the sampling error of 200 draws, about 10 %).
TEST(DetectPatternFit, NoiseSpreadMatchesReportedCovariance) {
  const Eigen::Vector2d at(20.3, 19.6);
  const Scene scene = perspectiveScene(at);
  constexpr int kDraws = 200;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero(), reported = Eigen::Matrix2d::Zero();
  std::vector<Eigen::Vector2d> errors;
  const cv::Mat linear = linearPatch(scene, 41, chessboardBlack, 1.0);
  for (int draw = 0; draw < kDraws; ++draw) {
    const cv::Mat grey = encodeGrey(linear, 2.0, 100 + draw);
    const PatternFit fit = fitLocalPattern(
        grey, startingAt(scene.H, at + Eigen::Vector2d(0.2, 0.1)), chessboardPattern());
    ASSERT_TRUE(fit.ok) << fit.why;
    errors.push_back(fit.px - at);
    mean += errors.back() / kDraws;
    reported += fit.covariance / kDraws;
  }
  for (const Eigen::Vector2d& e : errors)
    scatter += (e - mean) * (e - mean).transpose() / (kDraws - 1);
  const double spread = std::sqrt(scatter.trace() / 2), predicted = std::sqrt(reported.trace() / 2);
  std::printf("  noise 2: bias (%.4f, %.4f) px, spread %.4f px a coordinate, reported %.4f\n",
              mean.x(), mean.y(), spread, predicted);
  EXPECT_LT(mean.norm(), 4 * spread / std::sqrt(kDraws) + 0.003);
  EXPECT_GT(spread / predicted, 0.8);
  EXPECT_LT(spread / predicted, 1.25);
  EXPECT_LT(spread, 0.02);  // cornerSubPix on such corners: ~0.02-0.03 px
}

// ChArUco corner: the markers' corners 7 mm from it (a few pixels) are modelled, and their code
// bits (here a checker of cells) are kept out of the fit.
TEST(DetectPatternFit, CharucoCornerWithMarkersNearby) {
  const double s = 0.055, m = 0.041, g = 0.5 * (s - m), cell = m / 6;
  auto white_square = [](int r, int c) { return (r + c) % 2 == 1; };
  auto black = [&](const Eigen::Vector2d& b) {
    // Squares around the corner at (0, 0): (row, col) = (floor(y / s) + 1, floor(x / s) + 1).
    const int c = static_cast<int>(std::floor(b.x() / s)) + 1;
    const int r = static_cast<int>(std::floor(b.y() / s)) + 1;
    if (!white_square(r, c)) return true;
    const double mx = b.x() - ((c - 1) * s + g), my = b.y() - ((r - 1) * s + g);
    if (mx < 0 || my < 0 || mx >= m || my >= m) return false;
    const int bx = static_cast<int>(mx / cell), by = static_cast<int>(my / cell);
    if (bx == 0 || by == 0 || bx == 5 || by == 5) return true;  // border
    return (bx + by) % 2 == 0;                                  // code bits
  };
  const LocalPattern pattern = charucoCornerPattern(s, m, cell, 0, 0, white_square);
  double worst = 0;
  for (double dx : {0.1, 0.6}) {
    const Eigen::Vector2d at(20 + dx, 21 - dx);
    const Scene scene = perspectiveScene(at);
    const cv::Mat grey = renderPatch(scene, 41, black, 1.0);
    const PatternFit fit =
        fitLocalPattern(grey, startingAt(scene.H, at + Eigen::Vector2d(-0.3, 0.2)), pattern);
    ASSERT_TRUE(fit.ok) << fit.why;
    worst = std::max(worst, (fit.px - at).norm());
  }
  std::printf("  charuco corner, noise-free: worst error %.4f px\n", worst);
  EXPECT_LT(worst, 0.005);
}

// Lens bend: lines through the corner curved by a radial term (the thesis lens near an image
// corner: ~0.02 px of bend at the window's rim). With the bend measured from the neighbouring
// corners one square away the corner is found; taken as straight, the fit sits on the curves'
// mean, outwards.
TEST(DetectPatternFit, BentLinesNeedTheirBend) {
  const Eigen::Vector2d target(20.4, 20.2), lens_centre = target - Eigen::Vector2d(480, 420);
  const double k = 3.1e-7;  // k1 = 0.2 at f = 800 px (the thesis lens), 640 px from its centre
  Eigen::Vector2d at = target;  // where the unbent image puts the corner: bend(at) = target
  for (int it = 0; it < 20; ++it)
    at += target - (lens_centre + (at - lens_centre) * (1 + k * (at - lens_centre).squaredNorm()));
  Scene scene = perspectiveScene(at, 10, 1.0);
  scene.lens_centre = lens_centre;
  scene.k = k;
  const Eigen::Vector2d truth = scene.project(Eigen::Vector2d::Zero());
  const cv::Mat grey = renderPatch(scene, 41, chessboardBlack, 1.0);
  // The neighbours: one square before and a quarter square after along x, one square either
  // side along y.
  LineBending bending;
  bending.along_x = {true, -kSquare, 0.25 * kSquare, scene.project({-kSquare, 0}), truth,
                     scene.project({0.25 * kSquare, 0})};
  bending.along_y = {true, -kSquare, kSquare, scene.project({0, -kSquare}), truth,
                     scene.project({0, kSquare})};
  // The local homography of the bent image at the corner (what neighbouring points give).
  std::vector<Eigen::Vector2d> from, to;
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j) {
      from.emplace_back(i * kSquare, j * kSquare);
      to.push_back(scene.project(from.back()));
    }
  std::vector<cv::Point2f> a, b;
  for (size_t n = 0; n < from.size(); ++n) {
    a.emplace_back(static_cast<float>(from[n].x()), static_cast<float>(from[n].y()));
    b.emplace_back(static_cast<float>(to[n].x()), static_cast<float>(to[n].y()));
  }
  const cv::Mat H_cv = cv::findHomography(a, b);
  Eigen::Matrix3d H;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) H(r, c) = H_cv.at<double>(r, c);
  const Eigen::Matrix3d start = startingAt(H, truth + Eigen::Vector2d(0.2, 0.2));
  const PatternFit bent = fitLocalPattern(grey, start, chessboardPattern(), {}, bending);
  const PatternFit straight = fitLocalPattern(grey, start, chessboardPattern());
  ASSERT_TRUE(bent.ok && straight.ok) << bent.why << " / " << straight.why;
  const Eigen::Vector2d outwards = (truth - scene.lens_centre).normalized();
  std::printf("  bent lines: error %.4f px with the bend, %.4f px (%.4f outwards) without\n",
              (bent.px - truth).norm(), (straight.px - truth).norm(),
              (straight.px - truth).dot(outwards));
  EXPECT_LT((bent.px - truth).norm(), 0.004);
  EXPECT_GT((straight.px - truth).dot(outwards), 0.003);
}

}  // namespace
}  // namespace previz::calib::detail
