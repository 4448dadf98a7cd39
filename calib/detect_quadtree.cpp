// Quadtree ArUco board (core/board.h): OpenCV's ArUco detector finds the markers; the board's
// ids are kept; a marker whose corners disagree with a homography fitted (RANSAC) to the
// markers around it is dropped (a misread code, a foreign marker with a board id, a print whose
// ids start elsewhere); every corner of the others is refined by cornerSubPix, with a window
// that stays inside the marker's black border bit and clear of the neighbouring markers, and
// then from the marker's two edges through it (core/marker_edges.h; DetectOptions::model_fit).
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <string>

#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>

#include "calib/detail/detect_common.h"
#include "core/marker_edges.h"

namespace previz::calib::detail {

namespace {

struct Found {
  int index = 0;                         // marker index (core/board.h quadtreeMarkers order)
  std::array<Eigen::Vector2d, 4> px;     // tl, tr, br, bl as printed (OpenCV's order)
  std::array<Eigen::Vector2d, 4> board;  // the same corners, board frame (metres)
  double edge_px = 0;                    // shortest edge in the image
};

std::array<Eigen::Vector2d, 4> markerCorners(const QuadtreeMarker& m) {
  const Eigen::Vector2d& p = m.top_left;
  const double e = m.edge_m;
  return {p, p + Eigen::Vector2d(e, 0), p + Eigen::Vector2d(e, e), p + Eigen::Vector2d(0, e)};
}

}  // namespace

void detectQuadtree(const DetectInput& input, const BoardSpec& board, ViewObservations& out) {
  const DetectOptions& options = input.options();
  const std::vector<QuadtreeMarker> layout = quadtreeMarkers(board);
  const int n_markers = static_cast<int>(layout.size());

  std::vector<Found> found;
  for (const BoardMarker& marker : detectBoardMarkers(input, board, n_markers, out)) {
    Found f;
    f.index = marker.index;
    f.board = markerCorners(layout[static_cast<size_t>(marker.index)]);
    f.px = marker.px;
    f.edge_px = marker.edge_px;
    found.push_back(f);
  }
  if (found.empty()) return;  // out.failure says why

  // Layout check: each marker against a RANSAC homography of the markers whose centres lie
  // within 1.5 outer cells of its own (small enough for the lens to be a homography there to a
  // pixel or two). A marker read with another marker's id is off by at least a whole (sub-)
  // cell, 1.25 marker edges; a quarter edge (at least 2 px) separates the two. A marker with
  // fewer than two neighbours to check against is dropped: a print whose ids start elsewhere
  // than the board says leaves such lone markers with wrong ids (tests/calib/detect_test).
  const double s = board.square_m;
  auto centre = [](const std::array<Eigen::Vector2d, 4>& c) {
    return Eigen::Vector2d(0.25 * (c[0] + c[1] + c[2] + c[3]));
  };
  std::vector<bool> consistent(found.size(), true);
  int inconsistent = 0, unchecked = 0;
  for (size_t k = 0; k < found.size(); ++k) {
    const Eigen::Vector2d own = centre(found[k].board);
    std::vector<cv::Point2f> from, to;
    for (size_t j = 0; j < found.size(); ++j) {
      if (j == k || (centre(found[j].board) - own).lpNorm<Eigen::Infinity>() > 1.5 * s) continue;
      for (int q = 0; q < 4; ++q) {
        from.emplace_back(static_cast<float>(found[j].board[q].x()),
                          static_cast<float>(found[j].board[q].y()));
        to.emplace_back(static_cast<float>(found[j].px[q].x()),
                        static_cast<float>(found[j].px[q].y()));
      }
    }
    const double tol = std::max(2.0, 0.25 * found[k].edge_px);
    const cv::Mat H =
        from.size() < 8 ? cv::Mat() : cv::findHomography(from, to, cv::RANSAC, 0.5 * tol);
    if (H.empty()) {
      consistent[k] = false;
      ++unchecked;
      continue;
    }
    std::vector<cv::Point2f> own_board, predicted;
    for (int q = 0; q < 4; ++q)
      own_board.emplace_back(static_cast<float>(found[k].board[q].x()),
                             static_cast<float>(found[k].board[q].y()));
    cv::perspectiveTransform(own_board, predicted, H);
    double deviation = 0;
    for (int q = 0; q < 4; ++q)
      deviation = std::max(deviation, std::hypot(predicted[q].x - found[k].px[q].x(),
                                                 predicted[q].y - found[k].px[q].y()));
    if (deviation > tol) {
      consistent[k] = false;
      ++inconsistent;
    }
  }

  // Refinement windows. Edges not through a marker corner: inside, the code bits one border
  // bit (edge / (bits + 2)) from both sides (quadrant-shaped: a window turned by 45 degrees
  // reaches them when w > bit); outside, the nearest other marker, a white gap away along a
  // board axis (reached when sqrt(2) w > gap). The gap between markers of one level is
  // cell - edge; next to the finer cells of the ring inside it is (cell - edge) * 3 / 4.
  const int cells = cv::aruco::getPredefinedDictionary(openCvDictionaryId(board.dictionary))->markerSize + 2;
  std::vector<cv::Point2f> pts;
  std::vector<RefineWindow> windows;
  std::vector<int> ids;
  std::vector<MarkerCorner> edge_corners;
  int too_small_window = 0;
  for (size_t k = 0; k < found.size(); ++k) {
    if (!consistent[k]) continue;
    const Found& f = found[k];
    const QuadtreeMarker& m = layout[static_cast<size_t>(f.index)];
    const double px_per_m = f.edge_px / m.edge_m;
    const double bit_m = m.edge_m / cells;
    const double gap_m = (m.cell_m - m.edge_m) * (m.level + 1 < board.levels ? 0.75 : 1.0);
    const double free_px = std::min(bit_m, gap_m / std::sqrt(2.0)) * px_per_m;
    RefineWindow window;
    if (options.subpixel)
      window = refineWindow(free_px, options);
    else
      window.half = options.subpixel_window_px;
    if (window.half == 0) {
      ++too_small_window;
      continue;
    }
    std::vector<Eigen::Vector2d> from(f.board.begin(), f.board.end()), to(f.px.begin(), f.px.end());
    Eigen::Matrix3d H;
    if (!fitGridHomography(from, to, H)) continue;
    for (int q = 0; q < 4; ++q) {
      if (nearBorder(f.px[q], input.size(), options.border_margin_px + window.half)) continue;
      ids.push_back(4 * f.index + q);
      pts.emplace_back(static_cast<float>(f.px[q].x()), static_cast<float>(f.px[q].y()));
      windows.push_back(window);
      MarkerCorner ec;
      ec.H = H;
      ec.corner = f.board[q];
      ec.along[0] = (f.board[(q + 1) % 4] - f.board[q]) / m.edge_m;
      ec.along[1] = (f.board[(q + 3) % 4] - f.board[q]) / m.edge_m;
      ec.px_per_unit = px_per_m;
      ec.edge_px = f.edge_px;
      ec.profile_half_px = std::min(bit_m, gap_m) * px_per_m;
      edge_corners.push_back(ec);
    }
  }
  std::vector<bool> ok(pts.size(), true);
  if (options.subpixel) ok = refineCorners(input, pts, windows);
  // The edge refinement (core/marker_edges.h) is this board's model-based stage (options.model_fit).
  if (options.subpixel && options.model_fit) {
    const cv::Mat& lin = input.linearImage();
    for (size_t k = 0; k < pts.size(); ++k) {
      if (!ok[k]) continue;
      const MarkerCorner& e = edge_corners[k];
      Eigen::Vector2d refined;
      const Eigen::Vector2d start(pts[k].x, pts[k].y);
      if (!refineCornerByEdges(lin, e, refined)) continue;
      if ((refined - start).norm() > 1.5) continue;  // not the same corner: keep cornerSubPix's
      pts[k] = cv::Point2f(static_cast<float>(refined.x()), static_cast<float>(refined.y()));
    }
  }
  for (size_t k = 0; k < pts.size(); ++k)
    if (ok[k]) out.points.push_back({ids[k], Eigen::Vector2d(pts[k].x, pts[k].y)});
  if (out.points.empty())
    out.failure = std::to_string(found.size()) + " markers of this board found but none usable (" +
                  std::to_string(inconsistent) + " off the board layout, " +
                  std::to_string(unchecked) + " without neighbours to check them, " +
                  std::to_string(too_small_window) + " too small to refine)";
}

}  // namespace previz::calib::detail
