// Quadtree ArUco board (core/board.h): OpenCV's ArUco detector finds the markers; the board's
// ids are kept; a marker whose corners disagree with a homography fitted (RANSAC) to the
// markers around it is dropped (a misread code, a foreign marker with a board id, a print whose
// ids start elsewhere); every corner of the others is refined by cornerSubPix, with a window
// that stays inside the marker's black border bit and clear of the neighbouring markers, and
// then from the marker's two edges through it (EdgeCorner below; DetectOptions::model_fit).
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <string>

#include <Eigen/Eigenvalues>
#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>

#include "calib/detail/detect_common.h"

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

// A marker corner refined from its two edges: each edge's position is measured across it
// (the centroid of the intensity step on linear light, along the image normal) at points
// from 3 px to min(0.45 edge, 16 px) away from the corner, a line is fitted through them, and
// the corner is where the two lines meet. Why not cornerSubPix alone: an L-shaped corner is
// not point-symmetric, and under blur its rounded tip pulls cornerSubPix's gradient condition
// into the black (on the studio's quadtree views, 1 px blur: 0.3 px median, diagonally into
// the marker); a straight edge's step, away from the tip, is symmetric, so its centroid lies
// on the edge. The samples stay 3 px from the tip (the other edge's blur) and within 16 px
// (the lens bends edges: over 16 px at the test camera's k1 = -0.22 the sagitta is ~0.01 px).
struct EdgeCorner {
  Eigen::Matrix3d H;                 // board metres -> px, from the marker's 4 corners
  Eigen::Vector2d corner;            // board
  std::array<Eigen::Vector2d, 2> along;  // board unit vectors of its two edges (into the marker)
  double px_per_m = 0, edge_px = 0;
  double profile_half_px = 0;        // clear distance across the edge: border bit, white gap
};

float bilinear(const cv::Mat& lin, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= lin.cols || y0 + 1 >= lin.rows) return NAN;
  const double fx = x - x0, fy = y - y0;
  const float* r0 = lin.ptr<float>(y0);
  const float* r1 = lin.ptr<float>(y0 + 1);
  return static_cast<float>((1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
                            fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]));
}

bool refineByEdges(const cv::Mat& lin, const EdgeCorner& e, Eigen::Vector2d& out) {
  auto H = [&](const Eigen::Vector2d& b) {
    return Eigen::Vector2d((e.H * b.homogeneous()).hnormalized());
  };
  const double t0_px = 3.0, t1_px = std::min(0.45 * e.edge_px, 16.0);
  if (t1_px - t0_px < 1.5) return false;
  const double R = std::clamp(0.9 * e.profile_half_px, 1.5, 4.0), step = 0.25;
  std::array<Eigen::Vector3d, 2> lines;  // a x + b y = c, (a, b) unit
  for (int side = 0; side < 2; ++side) {
    const Eigen::Vector2d u = e.along[side], outward = -e.along[1 - side];
    std::vector<Eigen::Vector2d> points;
    for (double t = t0_px; t <= t1_px + 1e-9; t += 1.0) {
      const Eigen::Vector2d b = e.corner + (t / e.px_per_m) * u;
      const Eigen::Vector2d p = H(b);
      const Eigen::Vector2d n = (H(b + outward / e.px_per_m) - p).normalized();
      double c = 0;
      bool good = true;
      for (int it = 0; it < 3 && good; ++it) {
        double sw = 0, sd = 0;
        float prev = bilinear(lin, p.x() + (c - R) * n.x(), p.y() + (c - R) * n.y());
        for (double d = c - R + step; d <= c + R + 1e-9; d += step) {
          const float v = bilinear(lin, p.x() + d * n.x(), p.y() + d * n.y());
          if (!std::isfinite(v) || !std::isfinite(prev)) {
            good = false;
            break;
          }
          const double g = std::max(0.0, static_cast<double>(v - prev));  // dark -> light
          sw += g;
          sd += g * (d - 0.5 * step);
          prev = v;
        }
        if (!good || sw < 0.05) {
          good = false;
          break;
        }
        const double next = sd / sw;
        if (std::abs(next) > R) {
          good = false;
          break;
        }
        c = next;
      }
      if (good) points.push_back(p + c * n);
    }
    if (points.size() < 2) return false;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& q : points) mean += q;
    mean /= static_cast<double>(points.size());
    Eigen::Matrix2d S = Eigen::Matrix2d::Zero();
    for (const auto& q : points) S += (q - mean) * (q - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(S);
    const Eigen::Vector2d normal = eig.eigenvectors().col(0);  // smallest: across the line
    lines[side] = Eigen::Vector3d(normal.x(), normal.y(), normal.dot(mean));
  }
  Eigen::Matrix2d A;
  A << lines[0].x(), lines[0].y(), lines[1].x(), lines[1].y();
  if (std::abs(A.determinant()) < 0.2) return false;  // edges near parallel: not a corner
  out = A.inverse() * Eigen::Vector2d(lines[0].z(), lines[1].z());
  return out.allFinite();
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
  std::vector<EdgeCorner> edge_corners;
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
      EdgeCorner ec;
      ec.H = H;
      ec.corner = f.board[q];
      ec.along[0] = (f.board[(q + 1) % 4] - f.board[q]) / m.edge_m;
      ec.along[1] = (f.board[(q + 3) % 4] - f.board[q]) / m.edge_m;
      ec.px_per_m = px_per_m;
      ec.edge_px = f.edge_px;
      ec.profile_half_px = std::min(bit_m, gap_m) * px_per_m;
      edge_corners.push_back(ec);
    }
  }
  std::vector<bool> ok(pts.size(), true);
  if (options.subpixel) ok = refineCorners(input, pts, windows);
  // The edge refinement (EdgeCorner above) is this board's model-based stage (options.model_fit).
  if (options.subpixel && options.model_fit) {
    const cv::Mat& lin = input.linearImage();
    for (size_t k = 0; k < pts.size(); ++k) {
      if (!ok[k]) continue;
      const EdgeCorner& e = edge_corners[k];
      Eigen::Vector2d refined;
      const Eigen::Vector2d start(pts[k].x, pts[k].y);
      if (!refineByEdges(lin, e, refined)) continue;
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
