#pragma once
// Model-based sub-pixel refinement of a board point: the board's printed pattern around the
// point is known (black squares, marker borders), so instead of cornerSubPix's gradient
// condition the image patch is fitted, by maximum likelihood, with that pattern mapped through
// the local homography, blurred by a Gaussian and sRGB-encoded. Internal to previz_calib.
//
// Why: on the thesis scene (tests/calib) cornerSubPix's noise error was about twice the
// Cramér–Rao bound of its own window (0.020 px against 0.011 px a coordinate for the
// chessboard), and its window had to stay clear of every edge not through the corner, which on
// ChArUco boards (markers 2.8-5.6 px from the corner) leaves 2-5 px half windows whose rim
// catches the markers' blurred edges unevenly under perspective (-0.07 px in f on noise-free
// renders). The fit models those marker edges, so they inform the fit instead of biasing it.
//
// The blurred pattern is exact: a black region is a union of wedges (convex cones: the black
// squares around a chessboard corner, the corners of the ChArUco markers next to it), and a
// wedge blurred by an isotropic Gaussian is a bivariate normal probability
// (bivariateNormalCdf). Pixels are point samples of that blur (the pixel's own box is absorbed
// in the fitted sigma: box(1 px) = variance 1/12).
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace previz::calib::detail {

// P(X < h, Y < k) for standard normals with correlation r, |r| <= 0.925 (Genz 2004,
// "Numerical computation of rectangular bivariate and trivariate normal probabilities",
// Drezner & Wesolowsky's formula with 6/12/20-point Gauss-Legendre; absolute error < 5e-16).
// Returns NaN for |r| > 0.925 (edges within 22 degrees of parallel: not fitted).
double bivariateNormalCdf(double h, double k, double r);

// One black wedge of the local pattern, in board metres relative to the point being refined:
// the cone apex + s e1 + t e2 (s, t >= 0); e1, e2 not parallel, angle below 180 degrees.
struct PatternWedge {
  Eigen::Vector2d apex = Eigen::Vector2d::Zero();
  Eigen::Vector2d e1 = Eigen::Vector2d::UnitX(), e2 = Eigen::Vector2d::UnitY();
};

// The pattern around a board point: white paper with black wedges, exactly so within
// |x|, |y| < exact_half_m except inside the `unknown` boxes (e.g. marker bits), board metres
// relative to the point.
struct LocalPattern {
  std::vector<PatternWedge> black;
  double exact_half_m = 0;
  std::vector<Eigen::AlignedBox2d> unknown;
  // Distance from b to the nearest place where the pattern is not these wedges (0 there).
  double clearanceM(const Eigen::Vector2d& b) const;
};

// Chessboard inner corner (c, r) (core/board.h: corner at ((c + 1) s, (r + 1) s)): the two black
// squares around it, exact within one square. `black_square(sr, sc)` says whether square
// (row, column) is black.
template <typename IsBlack>
LocalPattern chessboardCornerPattern(double square_m, int r, int c, const IsBlack& black_square) {
  LocalPattern p;
  p.exact_half_m = square_m;
  for (int dr = 0; dr <= 1; ++dr)
    for (int dc = 0; dc <= 1; ++dc)
      if (black_square(r + dr, c + dc))
        p.black.push_back({Eigen::Vector2d::Zero(), Eigen::Vector2d(dc ? 1 : -1, 0),
                           Eigen::Vector2d(0, dr ? 1 : -1)});
  return p;
}

// ChArUco inner corner (c, r): the black squares around it plus, in each white square, the
// corner of its marker nearest to the point, exact within g + marker_m (g = (square_m -
// marker_m) / 2) (markers of marker_m centred in squares of
// square_m, a black border of border_m = marker_m / (bits + 2) around the code bits, which
// are unknown here).
template <typename IsWhite>
LocalPattern charucoCornerPattern(double square_m, double marker_m, double border_m, int r, int c,
                                  const IsWhite& white_square) {
  LocalPattern p;
  const double g = 0.5 * (square_m - marker_m);
  // A marker's wedge is its corner only up to the marker's far corners, g + marker_m away.
  p.exact_half_m = g + marker_m;
  for (int dr = 0; dr <= 1; ++dr)
    for (int dc = 0; dc <= 1; ++dc) {
      const double sx = dc ? 1 : -1, sy = dr ? 1 : -1;
      const Eigen::Vector2d e1(sx, 0), e2(0, sy);
      if (!white_square(r + dr, c + dc)) {
        p.black.push_back({Eigen::Vector2d::Zero(), e1, e2});
        continue;
      }
      p.black.push_back({Eigen::Vector2d(sx * g, sy * g), e1, e2});
      const double a = g + border_m, b = g + marker_m - border_m;
      p.unknown.emplace_back(Eigen::Vector2d(std::min(sx * a, sx * b), std::min(sy * a, sy * b)),
                             Eigen::Vector2d(std::max(sx * a, sx * b), std::max(sy * a, sy * b)));
    }
  return p;
}

// How the board's lines through the point bend in the image, from three points on each line:
// the point (at_px, as measured alongside the others: the fit's start may lie elsewhere) and two
// more at board offsets before_m < 0 < after_m along the line. Perspective keeps lines
// straight, so what the three points deviate from a line is the lens' bend; lines parallel to
// these (marker edges) bend alike. A line without both neighbours is taken as straight.
struct LineBending {
  struct Line {
    bool valid = false;
    double before_m = 0, after_m = 0;
    Eigen::Vector2d before_px = Eigen::Vector2d::Zero(), at_px = Eigen::Vector2d::Zero(),
                    after_px = Eigen::Vector2d::Zero();
  };
  Line along_x, along_y;  // board x and board y through the point
};

struct PatternFitOptions {
  double max_radius_px = 10;    // pixels farther than this from the start are not fitted
  bool srgb = true;             // grey = 255 * sRGB(linear radiance); else grey is linear
  double start_sigma_px = 1.2;  // blur guess (pattern blur plus the pixel box)
  // A pixel is fitted when the nearest unmodelled feature lies at least this many blur sigmas
  // away (its blurred edge is below 0.15 % of the contrast there).
  double clearance_sigmas = 3.0;
  int min_pixels = 24;
  int max_iterations = 12;
  double max_move_px = 1.5;     // farther from the start: not the same feature, refused
};

struct PatternFit {
  bool ok = false;
  std::string why;                      // when not ok
  Eigen::Vector2d px = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();  // of px, from the residual variance
  double blur_sigma_px = 0;
  double black = 0, white = 0;          // fitted levels (linear light when srgb)
  double rms_grey = 0;                  // residual RMS, grey levels
  int pixels = 0;
  int iterations = 0;
};

// grey: CV_8UC1. H_px_board maps board metres relative to the point to image pixels (the
// current estimate of the point is H(0)); its shape (the local perspective) is kept, the fit
// moves it in the image.
PatternFit fitLocalPattern(const cv::Mat& grey, const Eigen::Matrix3d& H_px_board,
                           const LocalPattern& pattern, const PatternFitOptions& options = {},
                           const LineBending& bending = {});

}  // namespace previz::calib::detail
