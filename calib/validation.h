#pragma once
// Honesty beyond RMS (mrcal's lesson: a low residual says the model fits these points, not that
// it projects well elsewhere). Two checks:
//  - projectionUncertainty: how far a pixel's projection may be off given the intrinsics'
//    covariance, over a grid of the image;
//  - crossValidate: calibrate two disjoint halves of the views, map how differently they
//    project, and compare that difference with what the covariances predict. A difference well
//    beyond the prediction means the model (or the data) is wrong, whatever the RMS says.
// Pixels: docs/conventions.md.
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "calib/intrinsics.h"
#include "calib/observations.h"
#include "core/board.h"

namespace previz::calib {

enum class UncertaintyMode {
  // The ray of each pixel is held fixed in the camera frame; only the intrinsics vary.
  // The distance does not matter.
  kIntrinsicsOnly,
  // mrcal's (2.x) mean-frames propagation: the point at distance_m along the pixel's ray is
  // fixed in every board frame, mapped back through each view's (uncertain) pose and averaged,
  // then projected; the joint covariance of intrinsics and poses is propagated. Part of a
  // principal-point error is a rotation of the camera frame, which this does not count
  // against projection. Needs IntrinsicsResult::joint_covariance.
  kMeanFrames,
};
const char* toString(UncertaintyMode mode);

struct UncertaintyOptions {
  UncertaintyMode mode = UncertaintyMode::kIntrinsicsOnly;
  int grid_cols = 32;        // grid points across the image (rows follow the aspect ratio)
  double distance_m = 2.0;   // kMeanFrames: depth (camera z) of the point on each pixel's ray
  void validate() const;     // throws Error naming the field
};

// A grid over the image; point (r, c) sits at pixel ((c + 0.5) W / cols - 0.5, (r + 0.5) H /
// rows - 0.5). Values are NaN where a pixel has no ray (past the lens' fold).
struct ImageGrid {
  int rows = 0, cols = 0;
  cv::Size image_size;
  // A fisheye's grid stops where the board was seen: within data_radius_px of the principal
  // point (the furthest used point; past it lies the dark rim outside the image circle, where
  // the model only extrapolates and its predicted uncertainty grows without bound). 0: the whole
  // image (Brown–Conrady lenses, whose sensor is lit to the corners).
  double data_radius_px = 0;
  Eigen::Vector2d principal_point = Eigen::Vector2d::Zero();
  Eigen::Vector2d pixel(int r, int c) const {
    return {(c + 0.5) * image_size.width / cols - 0.5, (r + 0.5) * image_size.height / rows - 0.5};
  }
  bool inside(int r, int c) const {
    return data_radius_px <= 0 || (pixel(r, c) - principal_point).norm() <= data_radius_px;
  }
};

struct UncertaintyMap {
  ImageGrid grid;
  // Worst-direction standard deviation of the projection (sqrt of the largest eigenvalue of the
  // 2 x 2 covariance), px. CV_64F, grid.rows x grid.cols.
  cv::Mat sigma_px;
  double mean_px = 0, max_px = 0;
  double centre_px = 0;      // at the grid point nearest the image centre
  double corners_px = 0;     // mean of the four corner grid points
  UncertaintyMode mode = UncertaintyMode::kIntrinsicsOnly;
};

// Needs result.covariance_ok. Throws Error otherwise (or, for kMeanFrames, without the joint
// covariance).
UncertaintyMap projectionUncertainty(const IntrinsicsResult& result,
                                     const UncertaintyOptions& options = {});

// How crossValidate splits the usable views into two halves.
enum class CrossValidationSplit {
  kAlternate,  // even- and odd-numbered views: two captures of the same kind
  // By where each view's points lie: views whose point centroid is nearer the image centre
  // than the median against the others. A model that cannot bend like the lens fits the
  // centre and the edges differently, so this split shows a wrong model more clearly.
  kCentreEdge,
};
const char* toString(CrossValidationSplit split);

struct CrossValidationOptions {
  IntrinsicsOptions solve;       // for both halves
  CrossValidationSplit split = CrossValidationSplit::kCentreEdge;
  int grid_cols = 32;
  // Compensate the rotation between the two solutions' camera frames before differencing (a
  // best-fit rotation over the grid, as mrcal's projection diff does): a principal point that
  // moves with a matching rotation changes nothing a rig calibration would not absorb.
  bool fit_rotation = true;
  // Flag when the RMS Mahalanobis distance of the difference, per image dimension, exceeds this
  // (1 is what a consistent pair gives on average).
  double max_normalised_rms = 2.0;
  void validate() const;         // throws Error naming the field
};

struct CrossValidationResult {
  IntrinsicsResult a, b;         // the halves (kCentreEdge: a = centre views, b = edge views)
  ImageGrid grid;
  cv::Mat diff_px;               // |projection difference| per grid point, CV_64F
  cv::Mat predicted_px;          // worst-direction std of the difference the covariances predict
  cv::Mat normalised;            // sqrt(d^T C^-1 d / 2) per grid point (~1 when consistent)
  double diff_rms_px = 0, diff_max_px = 0;
  double predicted_rms_px = 0;
  double normalised_rms = 0;     // sqrt(mean(d^T C^-1 d) / 2) over the grid
  double fraction_beyond_3sigma = 0;  // grid points with d^T C^-1 d > 11.83 (chi^2_2 at 3 sigma)
  bool consistent = false;       // normalised_rms <= max_normalised_rms
  std::string report() const;
};

// Splits the usable views (found, not rejected) into two halves (options.split), calibrates
// each, and compares them. Measured on the thesis camera (validation_test): a right model gives
// a normalised RMS of 0.5-1.5; k3 = 0.4 or -0.3 fitted with k3 held gives 2.7-7.6 with the
// centre/edge split, but only 0.8-5.8 with the alternate one, hence the default. Throws Error when a half cannot be calibrated.
CrossValidationResult crossValidate(const std::vector<ViewObservations>& views,
                                    const BoardSpec& board,
                                    const CrossValidationOptions& options = {});

}  // namespace previz::calib
