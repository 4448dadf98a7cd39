#pragma once
#include <array>
// Internals shared by the per-board detectors (calib/detect_*.cpp). Not a public header.
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "calib/detail/pattern_fit.h"
#include "calib/detect.h"

namespace previz::calib::detail {

// The image in the forms the detectors need, built once per call.
class DetectInput {
 public:
  DetectInput(const cv::Mat& image, const DetectOptions& options, const std::string& source);
  const cv::Mat& grey() const { return grey_; }  // CV_8UC1
  // linearImage() blurred by a Gaussian of sigma_px (0: linearImage()); each sigma asked for
  // is kept.
  const cv::Mat& prefilteredImage(double sigma_px) const;
  // Linear light without the pre-filter (circle edges need the unfiltered profile).
  const cv::Mat& linearImage() const;
  cv::Size size() const { return grey_.size(); }
  const DetectOptions& options() const { return options_; }

 private:
  cv::Mat grey_;
  mutable cv::Mat linear_;
  mutable std::map<double, cv::Mat> prefiltered_;
  DetectOptions options_;
};

// True when the pixel lies closer than margin to the image border (pixel-centre convention:
// the image spans [-0.5, size - 0.5]).
bool nearBorder(const Eigen::Vector2d& px, cv::Size size, double margin);

// The two reasons a detected marker or tag (its four corners) is skipped, the failure modes
// the thesis met: too small for the refinement window (shortest edge < min_marker_px) or too
// close to the image border (any corner within border_margin_px). Small is tested first.
enum class MarkerCheck { kOk, kTooSmall, kAtBorder };
MarkerCheck checkMarker(const std::array<Eigen::Vector2d, 4>& px, cv::Size size,
                        const DetectOptions& options, double* shortest_edge_px = nullptr);

// The board's ArUco markers in the image (ChArUco and quadtree boards): OpenCV's detector with
// parameters for small, soft markers (more threshold windows: 3, 7, ... 23 instead of 3, 13,
// 23; bits sampled at 8 px per cell and read from the middle 40 % of each cell; no corner
// refinement: the detectors refine the corners themselves). On 20 views of a 7 x 9
// DICT_4X4_250 board with 1 px blur and noise 2 (tests/calib/solve_fixtures.h) this decodes 606
// board markers instead of OpenCV's default 521, with no foreign id. Kept: ids in [first_id,
// first_id + n_markers) seen once (an id seen twice is ambiguous), passing checkMarker. None
// kept: out.failure says why (nothing decoded, or how many were too small / at the border).
struct BoardMarker {
  int index = 0;                      // id - board.first_id
  std::array<Eigen::Vector2d, 4> px;  // tl, tr, br, bl as printed (OpenCV's order)
  double edge_px = 0;                 // shortest edge in the image
};
std::vector<BoardMarker> detectBoardMarkers(const DetectInput& input, const BoardSpec& board,
                                            int n_markers, ViewObservations& out);

// The cornerSubPix half window of a point whose nearest edge NOT passing through it lies
// free_px away (measured in the worst direction, see the callers):
// min(subpixel_window_px, floor(free_px - 0.5)): half a pixel is left for the anti-aliasing of
// that edge (cornerSubPix weights the window's rim by exp(-1) and its corners by exp(-2)); on the
// studio's ChArUco and AprilGrid views a full pixel of clearance lost 3 % of the points and
// gained no accuracy. half = 0 when below 2 (too small: the point is dropped).
struct RefineWindow {
  int half = 0;
  double free_px = 0;  // distance to the nearest foreign edge (inf: none)
};
RefineWindow refineWindow(double free_px, const DetectOptions& options);

// Edge blur (sigma, px) of the image over the points' convex hull, from the focus measure
// (focus.h: sharpness ~ 0.8 / sigma); 0 when there are no edges to judge by.
double imageEdgeSigma(const DetectInput& input, const std::vector<cv::Point2f>& points);

// cornerSubPix with a half window per point. The image is the linear one pre-filtered towards
// options.prefilter_sigma_px: in full where the foreign edge lies at least twice the total edge
// sigma outside the window (chessboards, large tags: the filter averages noise and aliasing
// away), else only by what the image's own blur lacks of the target. Blur on blur next to a
// foreign edge made tight windows unstable: on AprilGrid views with 1 px defocus and noise 2, a
// full pre-filter turned 0.3 px tag corners into 1-1.7 px ones; while on chessboards in the
// same conditions the full filter gave 0.062 px median corners against 0.071 px without. A
// point whose
// refinement moved it by more than its half window (it wandered onto another feature) is
// marked false. Points with half 0 are left as they are and marked false.
std::vector<bool> refineCorners(const DetectInput& input, std::vector<cv::Point2f>& points,
                                const std::vector<RefineWindow>& windows);

// Model-based refinement (pattern_fit.h) after cornerSubPix, for the points marked in `to_fit`,
// when options().model_fit: point k is fitted with patterns[k] seen through H_px_board[k] (board
// metres relative to the point -> pixels; only its shape is used, it is moved onto points[k]
// first) with its lines bent by bending[k], over the pixels within kPatternFitRadiusPx that are
// clear of everything the pattern does not model. Fitted points are replaced (the others keep
// cornerSubPix's position); the result says which were. On the thesis scene (tests/calib) it
// took the chessboard's corner noise from 0.020 to 0.005 px a coordinate and the ChArUco
// corners' median error against the truth from 0.037 to 0.009 px.
constexpr double kPatternFitRadiusPx = 10.0;
std::vector<bool> fitPatterns(const DetectInput& input, std::vector<cv::Point2f>& points,
                              const std::vector<Eigen::Matrix3d>& H_px_board,
                              const std::vector<LocalPattern>& patterns,
                              const std::vector<LineBending>& bending,
                              const std::vector<bool>& to_fit);

// One line of a LineBending: the point and its neighbours before_m and after_m along the line
// (null: missing).
LineBending::Line bendLine(const Eigen::Vector2d* before, double before_m,
                           const Eigen::Vector2d& at, const Eigen::Vector2d* after,
                           double after_m);

// --- Grid orientation ------------------------------------------------------------------------
// A lattice of ni x nj nodes (i along the first axis) found in the image, some nodes possibly
// missing, has to be mapped onto the board's nc x nr grid (c along board x, r along board y).
// The 8 symmetries of the rectangle that fit the sizes are candidates; a board seen from its
// printed side keeps its handedness, which leaves rotations only; 'score' (lower is better,
// e.g. the mean grey of the squares that should be black) then picks among them, and the
// rotation whose board +x points most to the right in the image breaks remaining ties.
struct LatticeNode {
  int i = 0, j = 0;
  Eigen::Vector2d px;
};
struct GridMapping {
  int transform = -1;  // dihedral index, -1 = no consistent mapping
  // lattice (i, j) -> board grid (c, r)
  Eigen::Vector2i map(int i, int j) const;
  int ni = 0, nj = 0;
};
// score(mapping) may be empty (no colour cue). tie_fraction: scores within this fraction of
// the spread between the best and the worst candidate count as ties.
GridMapping chooseGridMapping(const std::vector<LatticeNode>& nodes, int ni, int nj, int nc, int nr,
                              const std::function<double(const GridMapping&)>& score = {});

// Least-squares homography from board-grid coordinates (c, r) to pixels; false if degenerate.
bool fitGridHomography(const std::vector<Eigen::Vector2d>& grid,
                       const std::vector<Eigen::Vector2d>& px, Eigen::Matrix3d& H);
Eigen::Vector2d applyHomography(const Eigen::Matrix3d& H, const Eigen::Vector2d& x);

// --- Per board type (detect_<type>.cpp). They fill out.points (unsorted ok) or out.failure.
void detectChessboard(const DetectInput& input, const BoardSpec& board, ViewObservations& out);
void detectCharuco(const DetectInput& input, const BoardSpec& board, ViewObservations& out);
void detectAprilGrid(const DetectInput& input, const BoardSpec& board, ViewObservations& out);
void detectCircles(const DetectInput& input, const BoardSpec& board, ViewObservations& out);
void detectQuadtree(const DetectInput& input, const BoardSpec& board, ViewObservations& out);

}  // namespace previz::calib::detail
