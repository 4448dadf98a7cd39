#pragma once
// Board detection for calibration: chessboard, ChArUco, AprilGrid, concentric circles.
// Returns board point ids (core/board.h boardPoints()) with sub-pixel positions; partial
// boards are fine. Never throws for "no board here": the result says why (failure).
#include <string>

#include <opencv2/core.hpp>

#include "calib/observations.h"
#include "core/board.h"

namespace previz::calib {

struct DetectOptions {
  bool subpixel = true;            // cornerSubPix (or the detector's own refinement)
  int subpixel_window_px = 5;      // half window; points nearer the border than it are dropped
  double border_margin_px = 3.0;   // extra margin: points/markers this close to the border dropped
  double min_marker_px = 12.0;     // markers/tags/circles smaller than this (edge, px) skipped
  // Chessboard squares smaller than this (px) skipped; 0 = none: a corner is refined in the
  // window its neighbours leave, and one too small for any keeps the detector's own position
  // (a small, far, slanted floor board; detect_test SmallSlantedBoards).
  double min_square_px = 0.0;
  int min_points = 6;              // fewer points than this = not found
  // 8-bit input is sRGB-encoded (as the studio renderer and most video cameras write it):
  // corners and circle edges are refined on the decoded, linear image. On the sRGB values
  // cornerSubPix is biased by 0.04-0.1 px (each edge's profile becomes asymmetric;
  // tests/datasets/render_test). Set false for a camera whose encoding is not sRGB-like: on
  // OpenCV's sample webcam images it raised the calibration RMS from 0.18 to 0.21 px.
  bool linear_light = true;
  // Edge width (Gaussian sigma, px) wanted on the image the corners are refined on; a sharper
  // image is pre-filtered up to it, a softer one is left alone (0 = never filter). Symmetric,
  // so it cannot move an X-junction's saddle; it tames pixel-level aliasing (with linear light it
  // took an analytic area-sampled board from 0.04-0.1 px to ~0.02 px, tests/datasets/render_test).
  // Larger values help big windows and hurt tight ones (1.4: ChArUco medians 0.036 px but 1 px
  // outliers next to the markers).
  double prefilter_sigma_px = 1.0;
  // After cornerSubPix, fit each chessboard and ChArUco corner with the board's printed pattern
  // around it (the squares, and the ChArUco markers' borders next to it) through the local
  // perspective and lens bend, by maximum likelihood (calib/detail/pattern_fit.h). On
  // the thesis scene (tests/calib) it took a chessboard corner's noise from 0.020 to 0.005 px a
  // coordinate and the median focal-length error from 0.065 to 0.004 px. AprilGrid corners keep
  // cornerSubPix (the code bits one cell from each corner leave a lopsided window, and the fit
  // came out biased there). Quadtree marker corners (L-shaped) are refined instead from the
  // marker's two edges through the corner (calib/detect_quadtree.cpp): 0.065 px median against
  // 0.317 px for cornerSubPix alone on the tests' views (tests/calib/detect_test).
  // false: cornerSubPix alone (OpenCV's pipeline; faster).
  bool model_fit = true;
  bool measure_focus = true;       // fill ViewObservations::focus (calib/focus.h measureFocus)
  void validate() const;           // throws Error naming the field
};

// image: 8-bit grey, BGR or BGRA. source names the image in messages ("left01.jpg",
// "frame 12"). Throws Error (file = source) for an empty image or another pixel type, and for
// invalid options or board; a board that is not there is reported in the result's 'failure'.
// Thread-safe (callers may run it over images in parallel; the AprilTag detector is one per
// thread) and deterministic.
//
// Refinement: cornerSubPix (then the model fit, see model_fit) with a half window per point, at
// most subpixel_window_px and small enough that no edge other than the corner's own enters it
// (chessboard: the next grid lines; ChArUco: the neighbouring markers; AprilGrid: the tag's
// first data cell and the far side of the corner square). A point whose window would be below 2 px is dropped, as is a marker,
// tag, square or circle smaller than min_marker_px, and a point nearer the border than
// border_margin_px + its window. ChArUco: a view whose markers contradict the board's layout
// (e.g. a legacy print read with the current layout: every corner would be one square off)
// gives nothing, with the reason. AprilGrid: corners that disagree with the tags around them
// (a tag merged with its corner squares) are dropped.
//
// Ids and orientation (the board frame is core/board.h's):
//  - the detected grid is mapped to board ids with the handedness of a board seen from its
//    printed side (board x to y turns clockwise in the image, like the image's u to v);
//  - chessboards whose two corner squares on a diagonal differ in colour (rows + cols odd, e.g.
//    7 x 10) are identified without ambiguity from the square colours; on symmetric ones (rows +
//    cols even) and on circle boards, which carry no orientation cue, the candidate orientation
//    whose board +x axis points most to the right in the image (largest u component at the
//    board centre) is chosen; a board turned near a quarter turn may thus flip between views.
//  - circle boards must be seen whole (every row and column present, single circles may be
//    missing): a partial grid of identical circles cannot be placed on the board.
ViewObservations detectBoard(const cv::Mat& image, const BoardSpec& board,
                             const DetectOptions& options = {}, const std::string& source = {});

}  // namespace previz::calib
