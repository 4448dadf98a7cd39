#pragma once
// Choosing which views to calibrate from, as they stream in (a live capture, a long video):
// the selector sees each view once and never holds more than the chosen set plus a small buffer
// of runners-up (SelectionOptions::buffer_size, default 4), so memory does not grow with the
// stream.
//
// Methods:
//  kUncertainty  (default) minimise the predicted mean projection variance over an image grid,
//                trace(Sigma G) with Sigma the inverse information and G the grid's sum of
//                d pixel / d intrinsics products (mrcal's criterion, A-optimal for projection).
//  kInformation  D-optimal design: maximise log det of the intrinsics' information
//                matrix, each view's contribution having its board pose marginalised out (Schur
//                complement of J^T J), plus a weak prior so that a poor set still scores finitely.
//                View contributions add, so a swap costs one small determinant.
//  Measured on the Table 5.2 captures (selection_test): both beat the thesis' greedy on c by
//  about 2x; kUncertainty is also better on f, where log det trades some f for distortion terms.
//  kPlaneAngles  the thesis' baseline, as we read it: board normals from PnP with the guess
//                camera; a new view replaces the member whose swap most increases the sum of
//                pairwise angles between normals.
//  kRandom       reservoir sampling (uniform over the stream, holds exactly N).
//  kSequential   the first N views.
// Information and normals are computed at a linearisation point: the guess camera (a nominal
// one when none is given) and the board pose solvePnP finds with it. Once the chosen set is
// full, the selector re-calibrates from the views it holds after relinearise_every, 2x, 4x, ...
// further usable views and recomputes their information at that estimate (a nominal guess can be 20 % off in f and
// know nothing of the distortion, which bends the information of wide views).
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "calib/intrinsics.h"
#include "calib/observations.h"
#include "core/board.h"
#include "core/camera.h"

namespace previz::calib {

enum class SelectionMethod { kUncertainty, kInformation, kPlaneAngles, kRandom, kSequential };
const char* toString(SelectionMethod method);
SelectionMethod selectionMethodFromString(const std::string& name);  // throws Error naming it

struct SelectionOptions {
  int views = 10;                   // size of the chosen set (N)
  SelectionMethod method = SelectionMethod::kUncertainty;
  int buffer_size = 4;              // runners-up held for later swaps (not for random/sequential)
  // Linearisation point. Unset: fx = fy = 0.8 * max(width, height) (about 73 degrees across the
  // long side), principal point at the centre, no distortion.
  std::optional<Camera> guess;
  LensModel model = LensModel::kBrownConrady;  // the lens model of the nominal guess (no guess given)
  IntrinsicLocks locks;             // held intrinsics are left out of the information
  double noise_px = 0.1;            // assumed detection noise, scales predicted sigmas only
  double min_improvement = 1e-6;    // a swap must raise the objective by this much
  int min_points = 6;               // views with fewer points are not considered
  int relinearise_every = 4;        // first re-calibration after this many views (0: never)
  std::uint64_t seed = 1;           // kRandom
  void validate() const;            // throws Error naming the field
};

class ViewSelector {
 public:
  ViewSelector(const BoardSpec& board, cv::Size image_size, const SelectionOptions& options = {});

  // Offers the next view of the stream (views without a board are counted and dropped).
  // Returns true when the view is in the chosen set afterwards.
  bool add(const ViewObservations& view);

  // The chosen views in stream order, and their stream indices (0-based, counting every view
  // offered).
  std::vector<ViewObservations> selected() const;
  std::vector<int> selectedIndices() const;

  int seen() const { return seen_; }           // views offered
  int considered() const { return considered_; }  // views with a usable board
  int held() const;                            // views held now (chosen + buffer)
  int maxHeld() const { return max_held_; }    // most ever held at once
  int swaps() const { return swaps_; }
  int relinearisations() const { return relinearisations_; }
  const Camera& linearisationCamera() const { return guess_; }
  double objective() const;                    // the method's score of the chosen set
  // Predicted standard deviations of the intrinsics (kIntrinsicNames order, 0 when held) from
  // the chosen set at noise_px; meaningful for every method (computed the same way).
  std::array<double, kIntrinsicCount> predictedSigma() const;
  std::string summary() const;

  const SelectionOptions& options() const { return options_; }

 private:
  struct Candidate {
    int index = -1;
    ViewObservations view;
    Eigen::MatrixXd information;   // marginal intrinsic information (free parameters), 1 px noise
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // board normal in the camera frame
  };
  bool prepare(const ViewObservations& view, Candidate& c) const;
  double score(const std::vector<const Candidate*>& set) const;
  double scoreWith(int skip, const Candidate* extra) const;  // chosen minus [skip] plus extra
  bool trySwap(Candidate& incoming);  // swaps incoming into chosen_ when it helps
  void trimBuffer();
  Eigen::MatrixXd sumInformation(const std::vector<const Candidate*>& set) const;
  void updateLinearisation();  // prior and uncertainty grid at guess_
  void relinearise();

  BoardSpec board_;
  cv::Size image_size_;
  SelectionOptions options_;
  Camera guess_;
  std::vector<int> free_;          // free intrinsic indices
  Eigen::MatrixXd prior_;          // weak prior information on the free intrinsics
  Eigen::MatrixXd grid_;           // kUncertainty: G over the image grid
  std::vector<Candidate> chosen_;
  std::vector<Candidate> buffer_;
  int seen_ = 0;
  int considered_ = 0;
  int max_held_ = 0;
  int swaps_ = 0;
  int relinearisations_ = 0;
  std::uint64_t rng_state_ = 0;
};

// Marginal information of one view about the free intrinsics (rows/cols in `free` order) at the
// given camera and board pose, for 1 px noise per coordinate: A - B D^-1 B^T over the view's
// points (A intrinsics-intrinsics, B intrinsics-pose, D pose-pose blocks of J^T J).
Eigen::MatrixXd marginalViewInformation(const Camera& camera, const Pose& T_cam_board,
                                        const ViewObservations& view, const BoardSpec& board,
                                        const std::vector<int>& free, double aspect_tie = 0.0);

}  // namespace previz::calib
