// ChArUco: OpenCV's ArUco detector finds the markers; each chessboard corner is predicted from a
// homography fitted to the detected markers around it and refined by cornerSubPix. The corner
// interpolation is ours rather than cv::aruco::interpolateCornersCharuco so that the board
// layout is the one core/board.h documents, for both the current and the legacy (OpenCV < 4.6,
// even row count) patterns, and so that a corner whose surrounding markers disagree with the
// layout (a legacy print detected with the current layout, a false marker) is dropped instead of
// being given a wrong id.
#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <string>

#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calib/detail/detect_common.h"
#include "core/error.h"

namespace previz::calib::detail {

namespace {

struct Marker {
  int square_r = 0, square_c = 0;
  std::array<Eigen::Vector2d, 4> px;     // tl, tr, br, bl as printed (OpenCV's order)
  std::array<Eigen::Vector2d, 4> board;  // the same corners, board frame (metres)
};

// Marker positions prove little about the layout: a print of the other ChArUco layout (legacy
// vs current, odd column count) is the assumed board moved by one square, so every local
// homography fits and every corner would be found with a wrong id. What betrays it: a marker
// inside the board that disagrees with its neighbours (a row's last marker that the other layout
// puts at the start of the next row), or a black square of the outer ring that is paper white
// (the shifted board's ring falls on the margin). Returns why the view is refused, or "".
// Markers that disagree with their neighbours outside the board's interior (stray detections)
// are removed.
std::string checkLayout(const cv::Mat& grey, const BoardSpec& board,
                        const std::function<bool(int, int)>& isWhite,
                        std::map<std::pair<int, int>, Marker>& by_square) {
  const double s = board.square_m;
  auto neighbourhood = [&](int r, int c, const Marker* skip, std::vector<cv::Point2f>& from,
                           std::vector<cv::Point2f>& to) {
    for (int sr = r - 2; sr <= r + 2; ++sr)
      for (int sc = c - 2; sc <= c + 2; ++sc) {
        const auto it = by_square.find({sr, sc});
        if (it == by_square.end() || &it->second == skip) continue;
        for (int q = 0; q < 4; ++q) {
          from.emplace_back(static_cast<float>(it->second.board[q].x()),
                            static_cast<float>(it->second.board[q].y()));
          to.emplace_back(static_cast<float>(it->second.px[q].x()),
                          static_cast<float>(it->second.px[q].y()));
        }
      }
  };
  std::vector<cv::Point2f> centres;
  for (const auto& [rc, mk] : by_square)
    centres.emplace_back(
        static_cast<float>(0.25 * (mk.px[0] + mk.px[1] + mk.px[2] + mk.px[3]).x()),
        static_cast<float>(0.25 * (mk.px[0] + mk.px[1] + mk.px[2] + mk.px[3]).y()));
  std::vector<cv::Point2f> hull;
  if (centres.size() >= 3) cv::convexHull(centres, hull);

  // A marker is checked against the homography of the markers around it when they surround it
  // (at least four, its centre inside theirs on the board: interpolation, not extrapolation).
  std::vector<std::pair<int, int>> stray;
  int interior_strays = 0;
  for (const auto& [rc, mk] : by_square) {
    std::vector<cv::Point2f> from, to, around;
    neighbourhood(rc.first, rc.second, &mk, from, to);
    for (size_t q = 0; q + 3 < from.size(); q += 4)
      around.push_back(0.25f * (from[q] + from[q + 1] + from[q + 2] + from[q + 3]));
    if (around.size() < 4) continue;
    std::vector<cv::Point2f> around_hull;
    cv::convexHull(around, around_hull);
    const cv::Point2f own_centre(static_cast<float>((rc.second + 0.5) * s),
                                 static_cast<float>((rc.first + 0.5) * s));
    if (cv::pointPolygonTest(around_hull, own_centre, false) < 0) continue;
    const double square_px = (mk.px[0] - mk.px[1]).norm() * s / board.marker_m;
    const cv::Mat H = cv::findHomography(from, to, cv::RANSAC, std::max(2.0, 0.1 * square_px));
    if (H.empty()) continue;
    std::vector<cv::Point2f> own, predicted;
    for (int q = 0; q < 4; ++q)
      own.emplace_back(static_cast<float>(mk.board[q].x()), static_cast<float>(mk.board[q].y()));
    cv::perspectiveTransform(own, predicted, H);
    double deviation = 0;
    for (int q = 0; q < 4; ++q)
      deviation = std::max(deviation,
                           cv::norm(predicted[q] - cv::Point2f(static_cast<float>(mk.px[q].x()),
                                                               static_cast<float>(mk.px[q].y()))));
    if (deviation < 0.4 * square_px) continue;
    const cv::Point2f centre(
        static_cast<float>(0.25 * (mk.px[0] + mk.px[1] + mk.px[2] + mk.px[3]).x()),
        static_cast<float>(0.25 * (mk.px[0] + mk.px[1] + mk.px[2] + mk.px[3]).y()));
    if (hull.size() >= 3 && cv::pointPolygonTest(hull, centre, true) > 0.5 * square_px)
      ++interior_strays;
    stray.push_back(rc);
  }
  // One misread marker (a 4x4 code read as another under blur) is dropped; several inside the
  // board mean the layout itself is wrong.
  if (interior_strays >= 2)
    return std::to_string(interior_strays) +
           " markers lie a square or more off the board layout: the print does not match the "
           "board (legacy_pattern, first_id or size?)";
  for (const auto& rc : stray) by_square.erase(rc);

  // Outer-ring black squares must be dark just inside their side that faces the board's
  // interior: under a one-square shift of the layout that point falls on the margin (paper),
  // which the square's centre may overshoot when the margin is narrower than half a square.
  // Dark = below the middle of the grey range of the nearest marker's square.
  const double inset = board.margin_m > 0 ? std::min(0.5 * board.margin_m, 0.25 * s) : 0.25 * s;
  std::vector<std::pair<int, int>> white_ring;
  for (int r = 0; r < board.rows; ++r)
    for (int c = 0; c < board.cols; ++c) {
      if (isWhite(r, c) || (r > 0 && c > 0 && r + 1 < board.rows && c + 1 < board.cols)) continue;
      std::vector<cv::Point2f> from, to;
      neighbourhood(r, c, nullptr, from, to);
      if (from.size() < 8) continue;
      const Marker* nearest = nullptr;
      int best = 1 << 30;
      for (const auto& [rc, mk] : by_square) {
        const int d = std::abs(rc.first - r) + std::abs(rc.second - c);
        if (d < best) {
          best = d;
          nearest = &mk;
        }
      }
      const double square_px = (nearest->px[0] - nearest->px[1]).norm() * s / board.marker_m;
      // RANSAC: a marker that the other layout puts elsewhere may still be among these.
      const cv::Mat H = cv::findHomography(from, to, cv::RANSAC, std::max(2.0, 0.1 * square_px));
      if (H.empty()) continue;
      std::vector<cv::Point2f> corners;
      for (const auto& x : nearest->px)
        corners.emplace_back(static_cast<float>(x.x()), static_cast<float>(x.y()));
      const cv::Rect box = cv::boundingRect(corners) & cv::Rect(0, 0, grey.cols, grey.rows);
      if (box.area() < 16) continue;
      const cv::Mat roi = grey(box);
      std::vector<std::uint8_t> values(roi.begin<std::uint8_t>(), roi.end<std::uint8_t>());
      std::sort(values.begin(), values.end());
      const double lo = values[values.size() / 10], hi = values[values.size() * 9 / 10];
      if (hi - lo < 20) continue;  // no contrast to judge by
      // Board points to sample: the middle of each interior-facing side, 'inset' inside.
      std::vector<cv::Point2f> q;
      const float cx = static_cast<float>((c + 0.5) * s), cy = static_cast<float>((r + 0.5) * s);
      const float near_side = static_cast<float>(0.5 * s - inset);
      if (c == 0) q.emplace_back(cx + near_side, cy);
      if (c + 1 == board.cols) q.emplace_back(cx - near_side, cy);
      if (r == 0) q.emplace_back(cx, cy + near_side);
      if (r + 1 == board.rows) q.emplace_back(cx, cy - near_side);
      std::vector<cv::Point2f> p;
      cv::perspectiveTransform(q, p, H);
      const double inset_px = inset * square_px / s;
      if (inset_px < 2.0) continue;  // too close to the square's edge to tell
      for (const cv::Point2f& x : p) {
        const int u = static_cast<int>(std::lround(x.x)), v = static_cast<int>(std::lround(x.y));
        if (u < 1 || v < 1 || u + 1 >= grey.cols || v + 1 >= grey.rows) continue;
        const double sample = cv::mean(grey(cv::Rect(u - 1, v - 1, 3, 3)))[0];
        if (sample > 0.5 * (lo + hi)) {
          white_ring.emplace_back(r, c);
          break;
        }
      }
    }
  // A shifted layout whitens every ring square of a side; one alone is more likely a
  // prediction off by a few pixels (an extrapolated corner of an oblique, distorted view).
  if (white_ring.size() >= 2)
    return std::to_string(white_ring.size()) + " black squares of the board's outer ring (e.g. (" +
           std::to_string(white_ring[0].first) + ", " + std::to_string(white_ring[0].second) +
           ")) are white in the image: the print does not match the board (legacy_pattern or "
           "size?)";
  return {};
}

}  // namespace

void detectCharuco(const DetectInput& input, const BoardSpec& board, ViewObservations& out) {
  const DetectOptions& options = input.options();
  const double s = board.square_m, m = board.marker_m, g = 0.5 * (s - m);

  // Layout (core/board.h, datasets/studio_board.cpp): square (r, c) is black when r + c is even,
  // flipped for legacy prints with an even row count; markers fill the white squares row-major.
  const bool flip = board.legacy_pattern && board.rows % 2 == 0;
  const std::function<bool(int, int)> isWhite = [flip](int r, int c) {
    return ((r + c) % 2 == 0) == flip;
  };
  std::vector<std::pair<int, int>> marker_square;
  for (int r = 0; r < board.rows; ++r)
    for (int c = 0; c < board.cols; ++c)
      if (isWhite(r, c)) marker_square.emplace_back(r, c);
  const int n_markers = static_cast<int>(marker_square.size());

  std::map<std::pair<int, int>, Marker> by_square;
  for (const BoardMarker& found : detectBoardMarkers(input, board, n_markers, out)) {
    Marker mk;
    mk.square_r = marker_square[static_cast<size_t>(found.index)].first;
    mk.square_c = marker_square[static_cast<size_t>(found.index)].second;
    const double x0 = mk.square_c * s + g, y0 = mk.square_r * s + g;
    mk.board = {Eigen::Vector2d(x0, y0), Eigen::Vector2d(x0 + m, y0),
                Eigen::Vector2d(x0 + m, y0 + m), Eigen::Vector2d(x0, y0 + m)};
    mk.px = found.px;
    by_square[{mk.square_r, mk.square_c}] = mk;
  }
  if (by_square.empty()) return;  // out.failure says why

  const std::string mismatch = checkLayout(input.grey(), board, isWhite, by_square);
  if (!mismatch.empty()) {
    out.failure = mismatch;
    return;
  }

  std::vector<cv::Point2f> pts;
  std::vector<RefineWindow> windows;
  std::vector<int> ids;
  std::vector<Eigen::Matrix3d> local_H;  // board metres relative to the corner -> px
  std::vector<LocalPattern> patterns;
  // The markers' black border: one bit cell of the dictionary's code grid plus its border.
  const double border_m =
      m / (cv::aruco::getPredefinedDictionary(openCvDictionaryId(board.dictionary))->markerSize + 2);
  for (int r = 0; r + 1 < board.rows; ++r)
    for (int c = 0; c + 1 < board.cols; ++c) {
      // Both white squares touching the corner must have their marker (OpenCV's minMarkers 2).
      std::vector<const Marker*> adjacent;
      for (int dr = 0; dr <= 1; ++dr)
        for (int dc = 0; dc <= 1; ++dc)
          if (isWhite(r + dr, c + dc)) {
            const auto it = by_square.find({r + dr, c + dc});
            if (it != by_square.end()) adjacent.push_back(&it->second);
          }
      if (adjacent.size() != 2) continue;
      // Homography from the markers of the 4 x 4 squares around the corner.
      std::vector<Eigen::Vector2d> from, to;
      for (int sr = r - 1; sr <= r + 2; ++sr)
        for (int sc = c - 1; sc <= c + 2; ++sc) {
          const auto it = by_square.find({sr, sc});
          if (it == by_square.end()) continue;
          for (int q = 0; q < 4; ++q) {
            from.push_back(it->second.board[q]);
            to.push_back(it->second.px[q]);
          }
        }
      Eigen::Matrix3d H;
      if (!fitGridHomography(from, to, H)) continue;
      const Eigen::Vector2d corner_board((c + 1) * s, (r + 1) * s);
      const Eigen::Vector2d predicted = applyHomography(H, corner_board);
      const double square_px =
          (applyHomography(H, corner_board + Eigen::Vector2d(s, 0)) - predicted).norm();
      double residual = 0;
      for (size_t q = 0; q < from.size(); ++q)
        residual = std::max(residual, (applyHomography(H, from[q]) - to[q]).norm());
      // Marker corners without refinement are good to about a pixel; a marker put on the wrong
      // square (layout mismatch, false detection) is off by a whole square.
      if (residual > std::max(1.5, 0.08 * square_px)) continue;
      // The nearest edges not through the corner are the adjacent markers' borders, g away
      // along both board axes: a window of half size w stays clear of them while w < g.
      double g_px = std::numeric_limits<double>::infinity();
      for (const Marker* mk : adjacent)
        for (int q = 0; q < 4; ++q)
          g_px = std::min(g_px, (mk->px[q] - predicted).norm() / std::sqrt(2.0));
      RefineWindow window;
      if (options.subpixel)
        window = refineWindow(g_px, options);
      else
        window.half = options.subpixel_window_px;
      const int w = window.half;
      if (w == 0) continue;
      if (nearBorder(predicted, input.size(), options.border_margin_px + w)) continue;
      ids.push_back(r * (board.cols - 1) + c);
      pts.emplace_back(static_cast<float>(predicted.x()), static_cast<float>(predicted.y()));
      windows.push_back(window);
      Eigen::Matrix3d to_corner = Eigen::Matrix3d::Identity();
      to_corner.block<2, 1>(0, 2) = corner_board;
      local_H.push_back(H * to_corner);
      patterns.push_back(charucoCornerPattern(s, m, border_m, r, c, isWhite));
    }
  std::vector<bool> ok(pts.size(), true);
  if (options.subpixel) ok = refineCorners(input, pts, windows);
  if (options.subpixel && options.model_fit) {
    // The model fit (detect_common.h) with the markers' corners next to each point modelled:
    // cornerSubPix's window must stay clear of them, and its rim still catches their blur
    // unevenly under perspective. Line bends from the refined neighbours one square away along
    // board x and y.
    std::map<int, Eigen::Vector2d> refined;
    for (size_t k = 0; k < pts.size(); ++k)
      if (ok[k]) refined[ids[k]] = Eigen::Vector2d(pts[k].x, pts[k].y);
    const int nc = board.cols - 1;
    auto find = [&](int c, int r) -> const Eigen::Vector2d* {
      if (c < 0 || r < 0 || c >= nc || r + 1 >= board.rows) return nullptr;
      const auto it = refined.find(r * nc + c);
      return it == refined.end() ? nullptr : &it->second;
    };
    std::vector<LineBending> bending(pts.size());
    for (size_t k = 0; k < pts.size(); ++k) {
      const int c = ids[k] % nc, r = ids[k] / nc;
      const Eigen::Vector2d here(pts[k].x, pts[k].y);
      bending[k].along_x = bendLine(find(c - 1, r), -s, here, find(c + 1, r), s);
      bending[k].along_y = bendLine(find(c, r - 1), -s, here, find(c, r + 1), s);
    }
    fitPatterns(input, pts, local_H, patterns, bending, ok);
  }
  for (size_t k = 0; k < pts.size(); ++k)
    if (ok[k]) out.points.push_back({ids[k], Eigen::Vector2d(pts[k].x, pts[k].y)});
  if (out.points.empty())
    out.failure = std::to_string(by_square.size()) +
                  " markers found but no chessboard corner with both its markers";
}

}  // namespace previz::calib::detail
