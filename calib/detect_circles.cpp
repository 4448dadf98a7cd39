// Concentric circles (the thesis' board): black ring [2R/3, R], white ring, black disc [0, R/3].
//
// 1. Markers: in a binarised image (Otsu and a coarse adaptive threshold), a dark region whose
//    hole contains a dark region, the three outlines fitting ellipses with agreeing centres and
//    the area ratios of the pattern (contour hierarchy, RETR_TREE).
// 2. Sub-pixel outlines: each of the three outlines is re-found along its normals as the
//    mid-level crossing of the linear-light profile and refitted (cv::fitEllipse).
// 3. Centre: under perspective (and lens distortion) the centre of a circle's image ellipse is
//    not the image of its centre; the offset grows with the radius squared (the ellipse centre is
//    the pole of the vanishing line: x(r) = (a + r^2 b) / (1 + r^2 c), c ~ (r tan(tilt) / Z)^2,
//    negligible). The three rings give the centre at r^2 = 1, 4/9, 1/9 (in R^2); a line fitted
//    through them, per image axis, is extrapolated to r = 0. A constant shift of every outline
//    (threshold level, blur, sRGB) keeps each ellipse's centre: it cancels as well.
// 4. Grid: grown from a seed marker by predicting each neighbour with an affine map fitted to
//    the already assigned markers within two lattice steps, then placed on the board
//    (chooseGridMapping: handedness, then board +x to the right).
#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <map>
#include <numeric>
#include <string>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "calib/detail/detect_common.h"
#include "core/units.h"

namespace previz::calib::detail {

namespace {

struct Ellipse {
  Eigen::Vector2d centre;
  double a = 0, b = 0;  // semi-axes along the rotated x and y
  double angle = 0;     // radians, of the 'a' axis
  Eigen::Vector2d point(double t) const {
    const double c = std::cos(angle), s = std::sin(angle);
    const Eigen::Vector2d local(a * std::cos(t), b * std::sin(t));
    return centre + Eigen::Vector2d(c * local.x() - s * local.y(), s * local.x() + c * local.y());
  }
  Eigen::Vector2d normal(double t) const {
    const double c = std::cos(angle), s = std::sin(angle);
    const Eigen::Vector2d local(std::cos(t) / a, std::sin(t) / b);
    return Eigen::Vector2d(c * local.x() - s * local.y(), s * local.x() + c * local.y())
        .normalized();
  }
  double minor() const { return std::min(a, b); }
  double major() const { return std::max(a, b); }
};

bool toEllipse(const cv::RotatedRect& r, Ellipse& e) {
  e.centre = Eigen::Vector2d(r.center.x, r.center.y);
  e.a = 0.5 * r.size.width;
  e.b = 0.5 * r.size.height;
  e.angle = radians(r.angle);
  return std::isfinite(e.a) && std::isfinite(e.b) && e.a > 0.5 && e.b > 0.5 && e.centre.allFinite();
}

bool fitEllipseTo(const std::vector<cv::Point2f>& pts, Ellipse& e) {
  if (pts.size() < 6) return false;
  return toEllipse(cv::fitEllipse(pts), e);
}

float bilinear(const cv::Mat& img, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= img.cols || y0 + 1 >= img.rows) return -1.0f;
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  const float* r0 = img.ptr<float>(y0);
  const float* r1 = img.ptr<float>(y0 + 1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
         fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
}

// Re-finds an outline along the normals of its current ellipse: the crossing of the level
// halfway between the profile's two ends (within +-half_px), then refits. band_fraction: the
// distance to the next outline, as a fraction of this outline's local radius.
bool refineOutline(const cv::Mat& linear, Ellipse& e, double band_fraction) {
  for (int iteration = 0; iteration < 2; ++iteration) {
    const int samples = std::clamp(static_cast<int>(2 * M_PI * e.major()), 24, 360);
    std::vector<cv::Point2f> edge;
    edge.reserve(static_cast<size_t>(samples));
    for (int k = 0; k < samples; ++k) {
      const double t = 2 * M_PI * k / samples;
      const Eigen::Vector2d p = e.point(t), n = e.normal(t);
      const double radius = (p - e.centre).norm();
      const double half = std::clamp(0.4 * band_fraction * radius, 0.75, 4.0);
      constexpr double kStep = 0.25;
      const int m = static_cast<int>(std::floor(half / kStep));
      std::vector<float> profile(static_cast<size_t>(2 * m + 1));
      bool inside = true;
      for (int q = -m; q <= m; ++q) {
        const Eigen::Vector2d x = p + q * kStep * n;
        const float v = bilinear(linear, x.x(), x.y());
        if (v < 0) inside = false;
        profile[static_cast<size_t>(q + m)] = v;
      }
      if (!inside) continue;
      const float lo = profile.front(), hi = profile.back();
      if (std::abs(hi - lo) < 0.05f) continue;  // no edge here (occluded, glare)
      const float level = 0.5f * (lo + hi);
      // The crossing nearest to the predicted outline.
      double best = std::numeric_limits<double>::infinity();
      for (int q = 0; q < 2 * m; ++q) {
        const float d0 = profile[static_cast<size_t>(q)] - level;
        const float d1 = profile[static_cast<size_t>(q + 1)] - level;
        if ((d0 <= 0) == (d1 <= 0)) continue;
        const double pos = (q - m + d0 / (d0 - d1)) * kStep;
        if (std::abs(pos) < std::abs(best)) best = pos;
      }
      if (!std::isfinite(best)) continue;
      const Eigen::Vector2d x = p + best * n;
      edge.emplace_back(static_cast<float>(x.x()), static_cast<float>(x.y()));
    }
    if (static_cast<int>(edge.size()) < samples / 2) return false;
    Ellipse refined;
    if (!fitEllipseTo(edge, refined)) return false;
    if ((refined.centre - e.centre).norm() > 0.5 * e.minor()) return false;
    e = refined;
  }
  return true;
}

struct Marker {
  Eigen::Vector2d centre;        // extrapolated to r = 0
  Eigen::Vector2d outer_centre;  // centre of the outer ellipse (for the record)
  Ellipse outer;
};

// Markers found in one binarisation (255 = dark).
void findMarkers(const cv::Mat& dark, const cv::Mat& linear, const DetectOptions& options,
                 std::vector<Marker>& markers) {
  std::vector<std::vector<cv::Point>> contours;
  std::vector<cv::Vec4i> hierarchy;
  cv::findContours(dark, contours, hierarchy, cv::RETR_TREE, cv::CHAIN_APPROX_NONE);
  const double min_area = 0.5 * M_PI * 0.25 * options.min_marker_px * options.min_marker_px * 0.25;
  auto largestChild = [&](int idx) {
    int best = -1;
    double best_area = 0;
    for (int c = hierarchy[idx][2]; c >= 0; c = hierarchy[c][0]) {
      const double a = cv::contourArea(contours[c]);
      if (a > best_area) {
        best_area = a;
        best = c;
      }
    }
    return best;
  };
  for (int idx = 0; idx < static_cast<int>(contours.size()); ++idx) {
    // Outer outlines of dark regions sit at even depths of the tree.
    int depth = 0;
    for (int p = hierarchy[idx][3]; p >= 0; p = hierarchy[p][3]) ++depth;
    if (depth % 2 != 0 || contours[idx].size() < 12) continue;
    const double area_a = cv::contourArea(contours[idx]);
    if (area_a < min_area) continue;
    const int hole = largestChild(idx);
    if (hole < 0 || contours[hole].size() < 8) continue;
    const int disc = largestChild(hole);
    if (disc < 0 || contours[disc].size() < 6) continue;
    const double area_h = cv::contourArea(contours[hole]), area_d = cv::contourArea(contours[disc]);
    // Ideal ratios 4/9 and 1/4; pixel outlines and thresholds move them.
    if (area_h / area_a < 0.2 || area_h / area_a > 0.75) continue;
    if (area_d / area_h < 0.06 || area_d / area_h > 0.55) continue;
    Ellipse ea, eh, ed;
    auto fit = [](const std::vector<cv::Point>& c, Ellipse& e) {
      std::vector<cv::Point2f> f(c.begin(), c.end());
      return fitEllipseTo(f, e);
    };
    if (!fit(contours[idx], ea) || !fit(contours[hole], eh) || !fit(contours[disc], ed)) continue;
    if (std::abs(area_a / (M_PI * ea.a * ea.b) - 1) > 0.2) continue;  // not an ellipse
    const double tol = 0.15 * ea.minor() + 1.0;
    if ((eh.centre - ea.centre).norm() > tol || (ed.centre - ea.centre).norm() > tol) continue;
    if (std::abs(eh.minor() / eh.major() - ea.minor() / ea.major()) > 0.25) continue;
    if (2 * ea.minor() < 0.5 * options.min_marker_px) continue;

    // Sub-pixel outlines; the next outline lies R/3 away: 1/3, 1/2 and 1 of the radii.
    if (options.subpixel && (!refineOutline(linear, ea, 1.0 / 3) ||
                             !refineOutline(linear, eh, 0.5) || !refineOutline(linear, ed, 1.0)))
      continue;
    // Extrapolate the centres to r^2 = 0 (least squares line in s = (r/R)^2 per axis).
    const double s[3] = {1.0, 4.0 / 9.0, 1.0 / 9.0};
    const Eigen::Vector2d c[3] = {ea.centre, eh.centre, ed.centre};
    const double s_mean = (s[0] + s[1] + s[2]) / 3;
    const Eigen::Vector2d c_mean = (c[0] + c[1] + c[2]) / 3;
    double sxx = 0;
    Eigen::Vector2d sxy = Eigen::Vector2d::Zero();
    for (int k = 0; k < 3; ++k) {
      sxx += (s[k] - s_mean) * (s[k] - s_mean);
      sxy += (s[k] - s_mean) * (c[k] - c_mean);
    }
    Marker m;
    m.centre = c_mean - s_mean * sxy / sxx;
    m.outer_centre = ea.centre;
    m.outer = ea;
    markers.push_back(m);
  }
}

}  // namespace

void detectCircles(const DetectInput& input, const BoardSpec& board, ViewObservations& out) {
  const DetectOptions& options = input.options();
  const cv::Mat& grey = input.grey();
  const cv::Mat& linear = input.linearImage();

  // Two binarisations: Otsu (even light) and a coarse adaptive threshold (light gradients); the
  // adaptive block must exceed the largest dark feature, so it is a sizeable part of the image.
  std::vector<Marker> found;
  cv::Mat dark;
  cv::threshold(grey, dark, 0, 255, cv::THRESH_BINARY_INV | cv::THRESH_OTSU);
  findMarkers(dark, linear, options, found);
  const int block = (std::max(31, std::min(grey.cols, grey.rows) / 4)) | 1;
  cv::adaptiveThreshold(grey, dark, 255, cv::ADAPTIVE_THRESH_MEAN_C, cv::THRESH_BINARY_INV, block,
                        10);
  findMarkers(dark, linear, options, found);
  // Merge the two lists: the same marker found twice keeps its first (Otsu) measurement.
  std::vector<Marker> markers;
  for (const Marker& m : found) {
    bool duplicate = false;
    for (const Marker& k : markers)
      duplicate = duplicate || (k.centre - m.centre).norm() < 0.5 * k.outer.minor();
    if (!duplicate) markers.push_back(m);
  }
  if (markers.empty()) {
    out.failure = "no concentric-circle markers found";
    return;
  }

  // --- Grow a lattice ---------------------------------------------------------------------------
  const int n = static_cast<int>(markers.size());
  const double pitch_over_radius = board.square_m / board.circle_radius_m;
  struct Lattice {
    std::map<std::pair<int, int>, int> node;  // (i, j) -> marker
  };
  auto grow = [&](int seed) {
    Lattice lattice;
    const Eigen::Vector2d p0 = markers[seed].centre;
    const double reach = 1.6 * pitch_over_radius * markers[seed].outer.major();
    std::vector<int> near;
    for (int k = 0; k < n; ++k)
      if (k != seed && (markers[k].centre - p0).norm() < reach) near.push_back(k);
    if (near.size() < 2) return lattice;
    std::sort(near.begin(), near.end(), [&](int a, int b) {
      return (markers[a].centre - p0).norm() < (markers[b].centre - p0).norm();
    });
    const Eigen::Vector2d u = markers[near[0]].centre - p0;
    Eigen::Vector2d v = Eigen::Vector2d::Zero();
    for (size_t q = 1; q < near.size(); ++q) {
      const Eigen::Vector2d d = markers[near[q]].centre - p0;
      if (std::abs(u.normalized().dot(d.normalized())) < 0.7) {
        v = d;
        break;
      }
    }
    if (v.isZero()) return lattice;
    std::vector<char> used(static_cast<size_t>(n), 0);
    lattice.node[{0, 0}] = seed;
    used[static_cast<size_t>(seed)] = 1;
    std::deque<std::pair<int, int>> queue{{0, 0}};
    while (!queue.empty()) {
      const auto [i, j] = queue.front();
      queue.pop_front();
      for (const auto& [di, dj] :
           {std::pair{1, 0}, std::pair{-1, 0}, std::pair{0, 1}, std::pair{0, -1}}) {
        const int ti = i + di, tj = j + dj;
        if (lattice.node.count({ti, tj})) continue;
        // Affine map from the assigned nodes within two steps of the target.
        std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> local;
        for (int a = ti - 2; a <= ti + 2; ++a)
          for (int b = tj - 2; b <= tj + 2; ++b) {
            const auto it = lattice.node.find({a, b});
            if (it != lattice.node.end())
              local.emplace_back(Eigen::Vector2d(a, b), markers[it->second].centre);
          }
        Eigen::Vector2d predicted, step_i = u, step_j = v;
        bool have_affine = false;
        if (local.size() >= 3) {
          Eigen::MatrixXd A(local.size(), 3);
          Eigen::MatrixXd B(local.size(), 2);
          for (size_t q = 0; q < local.size(); ++q) {
            A.row(q) << local[q].first.x(), local[q].first.y(), 1.0;
            B.row(q) = local[q].second.transpose();
          }
          Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
          if (svd.singularValues()(2) > 1e-6 * svd.singularValues()(0)) {
            const Eigen::MatrixXd X = svd.solve(B);  // 3 x 2
            step_i = X.row(0).transpose();
            step_j = X.row(1).transpose();
            predicted = X.transpose() * Eigen::Vector3d(ti, tj, 1.0);
            have_affine = true;
          }
        }
        if (!have_affine)
          predicted = markers[lattice.node[{i, j}]].centre + di * step_i + dj * step_j;
        const double tol = 0.3 * std::min(step_i.norm(), step_j.norm());
        int best = -1;
        double best_d = tol;
        for (int k = 0; k < n; ++k) {
          const double d = (markers[k].centre - predicted).norm();
          if (d < best_d) {
            best_d = d;
            best = k;
          }
        }
        if (best < 0 || used[static_cast<size_t>(best)]) continue;
        const double ratio =
            markers[best].outer.major() / markers[lattice.node[{i, j}]].outer.major();
        if (ratio < 0.6 || ratio > 1.6) continue;
        used[static_cast<size_t>(best)] = 1;
        lattice.node[{ti, tj}] = best;
        queue.emplace_back(ti, tj);
      }
    }
    return lattice;
  };
  // Seeds: markers near the middle of all markers first; keep the largest lattice.
  Eigen::Vector2d middle = Eigen::Vector2d::Zero();
  for (const Marker& m : markers) middle += m.centre;
  middle /= n;
  std::vector<int> order(static_cast<size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return (markers[a].centre - middle).norm() < (markers[b].centre - middle).norm();
  });
  Lattice best;
  for (int q = 0; q < std::min(n, 5); ++q) {
    Lattice l = grow(order[static_cast<size_t>(q)]);
    if (l.node.size() > best.node.size()) best = std::move(l);
    if (static_cast<int>(best.node.size()) >= board.rows * board.cols) break;
  }
  if (best.node.size() < 4) {
    out.failure = std::to_string(n) + " concentric-circle markers found but no grid of them";
    return;
  }
  // The growth's basis (nearest neighbour, then the nearest one not along it) may be a diagonal
  // of the board's grid when perspective shears it; any integer basis spans the same lattice,
  // and the board's own axes are those in which the circles fill the smallest box.
  {
    Eigen::Matrix2i best_m = Eigen::Matrix2i::Identity();
    long best_area = std::numeric_limits<long>::max();
    for (int a = -2; a <= 2; ++a)
      for (int b = -2; b <= 2; ++b)
        for (int c = -2; c <= 2; ++c)
          for (int d = -2; d <= 2; ++d) {
            if (std::abs(a * d - b * c) != 1) continue;
            Eigen::Matrix2i m;
            m << a, b, c, d;
            int i0 = 1 << 30, i1 = -(1 << 30), j0 = i0, j1 = i1;
            for (const auto& [ij, k] : best.node) {
              const Eigen::Vector2i t = m * Eigen::Vector2i(ij.first, ij.second);
              i0 = std::min(i0, t.x());
              i1 = std::max(i1, t.x());
              j0 = std::min(j0, t.y());
              j1 = std::max(j1, t.y());
            }
            const long area = static_cast<long>(i1 - i0 + 1) * (j1 - j0 + 1);
            if (area < best_area) {
              best_area = area;
              best_m = m;
            }
          }
    Lattice reduced;
    for (const auto& [ij, k] : best.node) {
      const Eigen::Vector2i t = best_m * Eigen::Vector2i(ij.first, ij.second);
      reduced.node[{t.x(), t.y()}] = k;
    }
    best = std::move(reduced);
  }
  int imin = 1 << 30, imax = -(1 << 30), jmin = imin, jmax = imax;
  for (const auto& [ij, k] : best.node) {
    imin = std::min(imin, ij.first);
    imax = std::max(imax, ij.first);
    jmin = std::min(jmin, ij.second);
    jmax = std::max(jmax, ij.second);
  }
  const int ni = imax - imin + 1, nj = jmax - jmin + 1;
  const bool fits =
      (ni == board.cols && nj == board.rows) || (ni == board.rows && nj == board.cols);
  if (!fits) {
    out.failure = "circle grid of " + std::to_string(ni) + " x " + std::to_string(nj) +
                  " found, the board has " + std::to_string(board.cols) + " x " +
                  std::to_string(board.rows) +
                  (ni * nj < board.rows * board.cols
                       ? ": a circle board has no orientation cue and must be seen whole"
                       : "");
    return;
  }
  std::vector<LatticeNode> nodes;
  for (const auto& [ij, k] : best.node)
    nodes.push_back({ij.first - imin, ij.second - jmin, markers[k].centre});
  const GridMapping mapping = chooseGridMapping(nodes, ni, nj, board.cols, board.rows);
  if (mapping.transform < 0) {
    out.failure = "circle grid found but degenerate (mirrored or collinear)";
    return;
  }
  for (const auto& [ij, k] : best.node) {
    const Marker& m = markers[k];
    // Small or cut by the border: the outline refinement needs the whole ring in the image.
    if (2 * m.outer.minor() < options.min_marker_px) continue;
    const double extent = m.outer.major() + 1.0;
    if (nearBorder(m.centre, input.size(), options.border_margin_px + extent)) continue;
    const Eigen::Vector2i cr = mapping.map(ij.first - imin, ij.second - jmin);
    out.points.push_back({cr.y() * board.cols + cr.x(), m.centre});
  }
  if (out.points.empty())
    out.failure = "circle grid found but every circle was too small or at the border";
}

}  // namespace previz::calib::detail
