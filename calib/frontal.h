#pragma once
// Iterative frontal refinement (Datta, Kim & Kanade 2009, "Accurate camera calibration using
// iterative refinement of control points"): with the current estimate, undistort and unwarp
// each view into a fronto-parallel image of the board (one remap: frontal pixel -> board point
// -> camera model -> source pixel), detect the board there, where circles are circles and
// corners are not foreshortened, map the detections back through the same model into the
// original image, and re-solve. Because the warp and the mapping back are the same function,
// a detection in the frontal image is exactly a detection in the original one; what improves
// is the detector's view (no perspective bias of circle centres, isotropic corner windows).
// One or two iterations carry most of the gain.
// Pixels: docs/conventions.md; board frame: core/board.h.
#include <array>
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "calib/detect.h"
#include "calib/intrinsics.h"
#include "calib/observations.h"
#include "core/board.h"
#include "core/camera.h"
#include "core/pose.h"

namespace previz::calib {

// What a frontal detection does to a point the original detection already had.
enum class FrontalReplace {
  // Circles: replace (a circle's centre is biased under perspective and unbiased in the
  // frontal image). Corners: keep the original position and only add the points found in the
  // frontal image alone (markers readable only once rectified). detectBoard's model fit already
  // takes the perspective and the lens bend into account in the original image, and the
  // resampling adds noise: on the thesis scene (frontal_test) ChArUco corners re-detected with
  // the true model came out at 0.0137 px median error against 0.0108 px in the original image
  // (0.0079 against 0.0061 with a continuous blur); replacing them moved the projection error
  // by +-50 % from seed to seed, no gain on average. With cornerSubPix alone
  // (DetectOptions::model_fit = false) replacing removes its perspective bias (noise-free
  // ChArUco f error -0.067 -> +0.016 px) but adds that noise.
  kAuto,
  kAll,      // replace every point (Datta et al.'s scheme)
  kNewOnly,  // only add points
};

struct FrontalOptions {
  int max_iterations = 3;
  // Stop when no intrinsic moves by more than this many of its standard deviations. Each
  // round resamples the image differently, so the estimate keeps moving by a fraction of a
  // sigma from round to round; smaller thresholds just spend rounds on noise.
  double converge_sigma = 0.5;
  // Frontal image resolution relative to the finest the board has in the view (1 = the
  // board's most magnified part keeps its pixel size; the rest is upsampled, and the detector's
  // sub-pixel window widened to match).
  double resolution = 1.0;
  int max_frontal_px = 4096;        // cap on either side of a frontal image
  // cv::INTER_LINEAR (1) or cv::INTER_CUBIC (2); cubic overshoots on noise and measured worse.
  int interpolation = 1;
  FrontalReplace replace = FrontalReplace::kAuto;
  // A frontal detection mapped back farther than this from the point it replaces is not the
  // same point (e.g. a symmetric board detected turned round) and is dropped.
  double max_shift_px = 2.0;
  DetectOptions detect;
  IntrinsicsOptions solve;          // locks, loss, ...; each round starts from the last estimate
  void validate() const;            // throws Error naming the field
};

struct FrontalIteration {
  int iteration = 0;                // 0: the estimate refinement started from
  Camera camera;
  std::array<double, kIntrinsicCount> sigma{};
  double rms_px = 0;
  int points = 0;
  int views_redetected = 0;         // views whose frontal image gave the board
  int views_kept = 0;               // views that kept their previous points (no frontal board)
  double mean_shift_px = 0;         // mean move of the points it re-detected
  double max_change_sigma = 0;      // largest |intrinsic change| / sigma against the round before
  double ms = 0;
};

struct FrontalResult {
  IntrinsicsResult result;                  // the final solve
  std::vector<ViewObservations> views;      // refined observations (original image pixels)
  std::vector<FrontalIteration> iterations; // [0] = start
  bool converged = false;
  std::string report() const;               // a table of the rounds
};

// The fronto-parallel image of the board in one view. The frontal pixel (u, v) shows board
// point (x0 + u / px_per_m, y0 + v / px_per_m, 0).
struct FrontalView {
  cv::Mat image;
  double px_per_m = 0;
  double x0_m = 0, y0_m = 0;
  double upsampling = 1;  // px_per_m over the board's median magnification in the view
  Eigen::Vector3d boardPoint(const Eigen::Vector2d& frontal_px) const {
    return {x0_m + frontal_px.x() / px_per_m, y0_m + frontal_px.y() / px_per_m, 0.0};
  }
};
FrontalView makeFrontalView(const cv::Mat& image, const Camera& camera, const Pose& T_cam_board,
                            const BoardSpec& board, const FrontalOptions& options = {});

// Re-detects one view in its frontal image and maps the points back into the original image
// (every point found there, whatever options.replace says). Points that move more than
// max_shift_px from `previous` are dropped; with no board found the result is empty (failure
// says why).
ViewObservations redetectFrontal(const cv::Mat& image, const ViewObservations& previous,
                                 const Camera& camera, const Pose& T_cam_board,
                                 const BoardSpec& board, const FrontalOptions& options = {});

// Refines `initial` (a solve of `views`). image_of(i) returns view i's image (loaded on demand,
// so long sequences need not sit in memory); views the initial solve left out stay out.
FrontalResult refineFrontal(const std::function<cv::Mat(size_t)>& image_of,
                            const std::vector<ViewObservations>& views, const BoardSpec& board,
                            const IntrinsicsResult& initial, const FrontalOptions& options = {});

}  // namespace previz::calib
