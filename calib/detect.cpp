#include "calib/detect.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include "calib/detail/detect_common.h"
#include "calib/focus.h"
#include "core/error.h"
#include "core/srgb.h"

namespace previz::calib {

namespace {

[[noreturn]] void optionError(const std::string& field, const std::string& what) {
  ErrorContext context;
  context.field = field;
  throw Error("detect: " + field + " " + what, context);
}

}  // namespace

void DetectOptions::validate() const {
  if (subpixel_window_px < 2 || subpixel_window_px > 50)
    optionError("subpixel_window_px",
                "must be in [2, 50] (got " + std::to_string(subpixel_window_px) + ")");
  if (!(std::isfinite(border_margin_px) && border_margin_px >= 0))
    optionError("border_margin_px",
                "must be a finite number >= 0 (got " + std::to_string(border_margin_px) + ")");
  if (!(std::isfinite(min_square_px) && min_square_px >= 0))
    optionError("min_square_px", "must be a finite number >= 0 (got " + std::to_string(min_square_px) + ")");
  if (!(std::isfinite(min_marker_px) && min_marker_px >= 4))
    optionError("min_marker_px",
                "must be a finite number >= 4 (got " + std::to_string(min_marker_px) + ")");
  if (!(std::isfinite(prefilter_sigma_px) && prefilter_sigma_px >= 0 && prefilter_sigma_px <= 5))
    optionError("prefilter_sigma_px",
                "must be in [0, 5] (got " + std::to_string(prefilter_sigma_px) + ")");
  if (min_points < 1)
    optionError("min_points", "must be >= 1 (got " + std::to_string(min_points) + ")");
}

namespace detail {

DetectInput::DetectInput(const cv::Mat& image, const DetectOptions& options,
                         const std::string& source)
    : options_(options) {
  ErrorContext context;
  context.file = source;
  const std::string name = source.empty() ? std::string("image") : "'" + source + "'";
  if (image.empty()) throw Error("detect: " + name + " is empty", context);
  if (image.depth() != CV_8U)
    throw Error("detect: " + name + " must be 8-bit (grey, BGR or BGRA); got depth " +
                    std::to_string(image.depth()) + " with " + std::to_string(image.channels()) +
                    " channels",
                context);
  switch (image.channels()) {
    case 1:
      grey_ = image;
      break;
    case 3:
      cv::cvtColor(image, grey_, cv::COLOR_BGR2GRAY);
      break;
    case 4:
      cv::cvtColor(image, grey_, cv::COLOR_BGRA2GRAY);
      break;
    default:
      throw Error("detect: " + name + " must have 1, 3 or 4 channels (got " +
                      std::to_string(image.channels()) + ")",
                  context);
  }
  if (!grey_.isContinuous()) grey_ = grey_.clone();
}

const cv::Mat& DetectInput::linearImage() const {
  if (linear_.empty()) {
    if (options_.linear_light) {
      const float* lut = srgb8ToLinear().data();
      linear_.create(grey_.size(), CV_32F);
      for (int v = 0; v < grey_.rows; ++v) {
        const std::uint8_t* in = grey_.ptr<std::uint8_t>(v);
        float* out = linear_.ptr<float>(v);
        for (int u = 0; u < grey_.cols; ++u) out[u] = lut[in[u]];
      }
    } else {
      grey_.convertTo(linear_, CV_32F, 1.0 / 255.0);
    }
  }
  return linear_;
}

const cv::Mat& DetectInput::prefilteredImage(double sigma_px) const {
  if (!(sigma_px > 0)) return linearImage();
  cv::Mat& out = prefiltered_[sigma_px];
  if (out.empty()) cv::GaussianBlur(linearImage(), out, cv::Size(0, 0), sigma_px);
  return out;
}

bool nearBorder(const Eigen::Vector2d& px, cv::Size size, double margin) {
  return !(px.x() >= -0.5 + margin && px.x() <= size.width - 0.5 - margin &&
           px.y() >= -0.5 + margin && px.y() <= size.height - 0.5 - margin);
}

MarkerCheck checkMarker(const std::array<Eigen::Vector2d, 4>& px, cv::Size size,
                        const DetectOptions& options, double* shortest_edge_px) {
  double edge = std::numeric_limits<double>::infinity();
  bool border = false;
  for (int q = 0; q < 4; ++q) {
    edge = std::min(edge, (px[q] - px[(q + 1) % 4]).norm());
    border = border || nearBorder(px[q], size, options.border_margin_px);
  }
  if (shortest_edge_px) *shortest_edge_px = edge;
  if (edge < options.min_marker_px) return MarkerCheck::kTooSmall;
  return border ? MarkerCheck::kAtBorder : MarkerCheck::kOk;
}

std::vector<BoardMarker> detectBoardMarkers(const DetectInput& input, const BoardSpec& board,
                                            int n_markers, ViewObservations& out) {
  const auto dictionary = cv::aruco::getPredefinedDictionary(openCvDictionaryId(board.dictionary));
  const auto params = cv::aruco::DetectorParameters::create();
  params->cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;
  params->adaptiveThreshWinSizeStep = 4;
  params->perspectiveRemovePixelPerCell = 8;
  params->perspectiveRemoveIgnoredMarginPerCell = 0.3;
  std::vector<std::vector<cv::Point2f>> corners, rejected;
  std::vector<int> ids;
  cv::aruco::detectMarkers(input.grey(), dictionary, corners, ids, params, rejected);

  std::map<int, int> seen;
  for (int id : ids) ++seen[id];
  std::vector<BoardMarker> found;
  int small = 0, at_border = 0;
  for (size_t k = 0; k < ids.size(); ++k) {
    const int index = ids[k] - board.first_id;
    if (index < 0 || index >= n_markers || seen[ids[k]] != 1) continue;
    BoardMarker m;
    m.index = index;
    for (int q = 0; q < 4; ++q) m.px[q] = Eigen::Vector2d(corners[k][q].x, corners[k][q].y);
    const MarkerCheck check = checkMarker(m.px, input.size(), input.options(), &m.edge_px);
    if (check == MarkerCheck::kTooSmall) {
      ++small;
    } else if (check == MarkerCheck::kAtBorder) {
      ++at_border;
    } else {
      found.push_back(m);
    }
  }
  if (found.empty())
    out.failure = ids.empty() ? "no ArUco markers of " + board.dictionary + " found"
                              : "no usable marker of this board (" + std::to_string(ids.size()) +
                                    " detected, " + std::to_string(small) + " too small, " +
                                    std::to_string(at_border) + " at the border)";
  return found;
}

RefineWindow refineWindow(double free_px, const DetectOptions& options) {
  RefineWindow w;
  w.half = options.subpixel_window_px;
  w.free_px = free_px;
  if (std::isfinite(free_px))
    w.half = std::min(w.half, static_cast<int>(std::floor(free_px - 0.5)));
  if (w.half < 2) return {};
  return w;
}

double imageEdgeSigma(const DetectInput& input, const std::vector<cv::Point2f>& points) {
  if (points.size() < 3) return 0;
  std::vector<Observation> region;
  for (const cv::Point2f& p : points) region.push_back({0, Eigen::Vector2d(p.x, p.y)});
  const FocusMeasure focus = measureFocus(input.grey(), region, input.options().linear_light);
  return focus.sharpness > 0 ? 0.8 / focus.sharpness : 0;  // focus.h: sharpness ~ 0.8 / sigma
}

std::vector<bool> refineCorners(const DetectInput& input, std::vector<cv::Point2f>& points,
                                const std::vector<RefineWindow>& windows) {
  std::vector<bool> ok(points.size(), false);
  const double target = input.options().prefilter_sigma_px;
  const double edge_sigma = target > 0 ? imageEdgeSigma(input, points) : 0;
  const double missing = target * target - edge_sigma * edge_sigma;
  const double topped_up = missing > 0.09 ? std::sqrt(missing) : 0.0;
  const double total = std::sqrt(edge_sigma * edge_sigma + target * target);
  // Per point: the full pre-filter where the foreign edge stays 2 sigma outside the window,
  // else only what the image lacks of the target.
  std::map<std::pair<int, double>, std::vector<size_t>> groups;
  for (size_t k = 0; k < points.size(); ++k) {
    const RefineWindow& w = windows[k];
    if (w.half <= 0) continue;
    const bool clear = !std::isfinite(w.free_px) || w.free_px - w.half >= 2.0 * total;
    groups[{w.half, clear ? target : topped_up}].push_back(k);
  }
  const cv::TermCriteria criteria(cv::TermCriteria::EPS | cv::TermCriteria::COUNT, 100, 1e-4);
  for (const auto& [key, members] : groups) {
    const int w = key.first;
    std::vector<cv::Point2f> pts;
    pts.reserve(members.size());
    for (size_t k : members) pts.push_back(points[k]);
    cv::cornerSubPix(input.prefilteredImage(key.second), pts, cv::Size(w, w), cv::Size(-1, -1),
                     criteria);
    for (size_t n = 0; n < members.size(); ++n) {
      const size_t k = members[n];
      const cv::Point2f d = pts[n] - points[k];
      const bool finite = std::isfinite(pts[n].x) && std::isfinite(pts[n].y);
      ok[k] = finite && std::abs(d.x) <= w && std::abs(d.y) <= w;
      if (finite) points[k] = pts[n];
    }
  }
  return ok;
}

std::vector<bool> fitPatterns(const DetectInput& input, std::vector<cv::Point2f>& points,
                              const std::vector<Eigen::Matrix3d>& H_px_board,
                              const std::vector<LocalPattern>& patterns,
                              const std::vector<LineBending>& bending,
                              const std::vector<bool>& to_fit) {
  std::vector<bool> fitted(points.size(), false);
  if (!input.options().model_fit) return fitted;
  PatternFitOptions options;
  options.max_radius_px = kPatternFitRadiusPx;
  options.srgb = input.options().linear_light;
  for (size_t k = 0; k < points.size(); ++k) {
    if (!to_fit[k]) continue;
    // Move the homography onto the point: a translation in the image.
    const Eigen::Vector2d at = (H_px_board[k] * Eigen::Vector3d(0, 0, 1)).hnormalized();
    Eigen::Matrix3d shift = Eigen::Matrix3d::Identity();
    shift(0, 2) = points[k].x - at.x();
    shift(1, 2) = points[k].y - at.y();
    const PatternFit fit =
        fitLocalPattern(input.grey(), shift * H_px_board[k], patterns[k], options, bending[k]);
    if (!fit.ok) continue;  // keeps cornerSubPix's position
    points[k] = cv::Point2f(static_cast<float>(fit.px.x()), static_cast<float>(fit.px.y()));
    fitted[k] = true;
  }
  return fitted;
}

LineBending::Line bendLine(const Eigen::Vector2d* before, double before_m,
                           const Eigen::Vector2d& at, const Eigen::Vector2d* after,
                           double after_m) {
  LineBending::Line line;
  if (!before || !after) return line;
  line.valid = true;
  line.before_m = before_m;
  line.after_m = after_m;
  line.before_px = *before;
  line.at_px = at;
  line.after_px = *after;
  return line;
}

Eigen::Vector2i GridMapping::map(int i, int j) const {
  switch (transform) {
    case 0:
      return {i, j};
    case 1:
      return {ni - 1 - i, nj - 1 - j};
    case 2:
      return {ni - 1 - i, j};
    case 3:
      return {i, nj - 1 - j};
    case 4:
      return {j, i};
    case 5:
      return {nj - 1 - j, ni - 1 - i};
    case 6:
      return {nj - 1 - j, i};
    case 7:
      return {j, ni - 1 - i};
  }
  return {-1, -1};
}

Eigen::Vector2d applyHomography(const Eigen::Matrix3d& H, const Eigen::Vector2d& x) {
  const Eigen::Vector3d y = H * x.homogeneous();
  return y.hnormalized();
}

bool fitGridHomography(const std::vector<Eigen::Vector2d>& grid,
                       const std::vector<Eigen::Vector2d>& px, Eigen::Matrix3d& H) {
  if (grid.size() < 4 || grid.size() != px.size()) return false;
  // Hartley normalisation of both point sets, then the DLT by SVD.
  auto normaliser = [](const std::vector<Eigen::Vector2d>& p) {
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& x : p) mean += x;
    mean /= static_cast<double>(p.size());
    double spread = 0;
    for (const auto& x : p) spread += (x - mean).norm();
    spread /= static_cast<double>(p.size());
    const double s = spread > 0 ? std::sqrt(2.0) / spread : 1.0;
    Eigen::Matrix3d T = Eigen::Matrix3d::Identity();
    T(0, 0) = T(1, 1) = s;
    T.block<2, 1>(0, 2) = -s * mean;
    return T;
  };
  const Eigen::Matrix3d Ta = normaliser(grid), Tb = normaliser(px);
  Eigen::MatrixXd A(2 * grid.size(), 9);
  for (size_t k = 0; k < grid.size(); ++k) {
    const Eigen::Vector3d a = Ta * grid[k].homogeneous();
    const Eigen::Vector3d b = Tb * px[k].homogeneous();
    A.row(2 * k) << 0, 0, 0, -b.z() * a.transpose(), b.y() * a.transpose();
    A.row(2 * k + 1) << b.z() * a.transpose(), 0, 0, 0, -b.x() * a.transpose();
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::VectorXd s = svd.singularValues();
  // Rank below 8: all points on a line (or too few distinct ones).
  if (s.size() < 8 || s(7) < 1e-9 * s(0)) return false;
  Eigen::VectorXd h = svd.matrixV().col(8);
  Eigen::Matrix3d Hn;
  Hn << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8);
  H = Tb.inverse() * Hn * Ta;
  if (!H.allFinite() || std::abs(H(2, 2)) < 1e-300) return false;
  H /= H(2, 2);
  return true;
}

GridMapping chooseGridMapping(const std::vector<LatticeNode>& nodes, int ni, int nj, int nc, int nr,
                              const std::function<double(const GridMapping&)>& score) {
  struct Candidate {
    GridMapping mapping;
    double score = 0;
    double right = 0;  // u component of the unit image direction of board +x
  };
  std::vector<Candidate> candidates;
  for (int k = 0; k < 8; ++k) {
    const bool swapped = k >= 4;
    if ((swapped ? nj : ni) != nc || (swapped ? ni : nj) != nr) continue;
    GridMapping m;
    m.transform = k;
    m.ni = ni;
    m.nj = nj;
    std::vector<Eigen::Vector2d> grid, px;
    for (const LatticeNode& n : nodes) {
      grid.push_back(m.map(n.i, n.j).cast<double>());
      px.push_back(n.px);
    }
    Eigen::Matrix3d H;
    if (!fitGridHomography(grid, px, H)) continue;
    // Image directions of board +x and +y at the middle of the grid.
    const Eigen::Vector2d centre(0.5 * (nc - 1), 0.5 * (nr - 1));
    const Eigen::Vector2d p0 = applyHomography(H, centre);
    const Eigen::Vector2d dx = applyHomography(H, centre + Eigen::Vector2d(0.5, 0)) - p0;
    const Eigen::Vector2d dy = applyHomography(H, centre + Eigen::Vector2d(0, 0.5)) - p0;
    // Printed side towards the camera: board x -> y turns like image u -> v (z into the board,
    // camera z forward, both right-handed).
    if (dx.x() * dy.y() - dx.y() * dy.x() <= 0) continue;
    Candidate c;
    c.mapping = m;
    c.right = dx.norm() > 0 ? dx.x() / dx.norm() : 0;
    c.score = score ? score(m) : 0.0;
    candidates.push_back(c);
  }
  if (candidates.empty()) return {};
  double best = std::numeric_limits<double>::infinity(), worst = -best;
  for (const Candidate& c : candidates) {
    best = std::min(best, c.score);
    worst = std::max(worst, c.score);
  }
  const double tie = best + 0.25 * (worst - best);
  const Candidate* chosen = nullptr;
  for (const Candidate& c : candidates) {
    if (c.score > tie) continue;
    if (!chosen || c.right > chosen->right) chosen = &c;
  }
  return chosen->mapping;
}

}  // namespace detail

ViewObservations detectBoard(const cv::Mat& image, const BoardSpec& board,
                             const DetectOptions& options, const std::string& source) {
  options.validate();
  try {
    board.validate();
  } catch (const Error& e) {
    ErrorContext context = e.context();
    if (context.file.empty()) context.file = source;
    throw Error(e.message(), context);
  }
  const detail::DetectInput input(image, options, source);
  ViewObservations out;
  out.source = source;
  out.image_size = input.size();
  try {
    switch (board.type) {
      case BoardType::kChessboard:
        detail::detectChessboard(input, board, out);
        break;
      case BoardType::kCharuco:
        detail::detectCharuco(input, board, out);
        break;
      case BoardType::kAprilGrid:
        detail::detectAprilGrid(input, board, out);
        break;
      case BoardType::kCircles:
        detail::detectCircles(input, board, out);
        break;
      case BoardType::kQuadtree:
        detail::detectQuadtree(input, board, out);
        break;
    }
  } catch (const cv::Exception& e) {
    ErrorContext context;
    context.file = source;
    throw Error("detect: OpenCV failed on '" + source + "': " + e.what(), context);
  }
  std::sort(out.points.begin(), out.points.end(),
            [](const Observation& a, const Observation& b) { return a.id < b.id; });
  if (!out.points.empty() && static_cast<int>(out.points.size()) < options.min_points) {
    out.failure = "only " + std::to_string(out.points.size()) + " points (< min_points " +
                  std::to_string(options.min_points) + ")";
    out.points.clear();
  }
  if (out.points.empty() && out.failure.empty()) out.failure = "no board found";
  if (options.measure_focus)
    out.focus = measureFocus(input.grey(), out.points, options.linear_light);
  return out;
}

}  // namespace previz::calib
