#pragma once
// What board detection hands to the intrinsic solve: per image, the board points found (ids
// from core/board.h boardPoints()) and their pixels, plus why an image gave nothing.
// Pixels follow docs/conventions.md ((0,0) = centre of the top-left pixel).
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace previz::calib {

struct Observation {
  int id = -1;                // board point id (core/board.h)
  Eigen::Vector2d px;         // detected pixel
};

// A tag / marker of the board as decoded (AprilGrid): its id, the code's bit errors (0 = the
// exact code) and whether its corners were used. A tag decoded with bit errors is used only when
// the corners of the tags around it confirm where it sits on the board.
struct DecodedTag {
  int id = -1;
  int bit_errors = 0;
  bool used = false;
  std::string why_not;  // when not used
};

struct FocusMeasure {
  double modified_laplacian = 0;    // Nayar's modified Laplacian, mean over the board region
  double variance_of_laplacian = 0; // variance of the Laplacian over the board region
  // Scale- and contrast-free sharpness (calib/focus.h): modified Laplacian over the gradient
  // magnitude on the board's edge pixels, noise floor removed; about 0.8 / edge blur sigma (px)
  // for blurred edges, ~2 for perfectly sharp ones. 0 when the region has no edges.
  double sharpness = 0;
  int edge_pixels = 0;              // pixels that entered 'sharpness'
};

struct ViewObservations {
  std::string source;                 // image path or "frame N" — used in every message
  cv::Size image_size;
  std::vector<Observation> points;    // empty when the board was not found
  std::string failure;                // why nothing was found / why the view was dropped
  std::vector<DecodedTag> tags;       // AprilGrid: every tag of the board decoded (else empty)
  FocusMeasure focus;
  bool rejected = false;              // set by focus rejection or view selection
  std::string rejected_reason;
  bool found() const { return !points.empty(); }
};

}  // namespace previz::calib
