#include "core/marker_edges.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

namespace previz {

namespace {

constexpr double kStep = 0.25;  // px between profile samples across the edge
constexpr double kMaxReachPx = 4.0;  // both callers clamp their reach to it
constexpr int kMaxSamples = static_cast<int>(2 * kMaxReachPx / kStep) + 1;

// Where the dark -> light step across the edge lies, along the unit normal n from p (the light
// side towards +n): the centroid of the differences over [c - R, c + R], re-centred 3 times,
// without the negative ones below -keep_negative x the largest (another edge's light -> dark
// step). keep_negative 0 keeps only the positive differences: robust to a neighbour's edge close
// by, but biased towards the light side under noise, which is stronger there in linear light
// (sRGB codes' noise grows with the decode's slope), and only its positive half is summed.
// False when R > kMaxReachPx, the profile leaves the image, has no step, or the step is beyond R.
bool stepOffset(const cv::Mat& lin, const Eigen::Vector2d& p, const Eigen::Vector2d& n, double R,
                double keep_negative, double& offset) {
  if (!(R <= kMaxReachPx)) return false;
  double c = 0;
  for (int it = 0; it < 3; ++it) {
    double g[kMaxSamples], at[kMaxSamples], g_max = 0;
    int count = 0;
    float prev = bilinearAt(lin, p.x() + (c - R) * n.x(), p.y() + (c - R) * n.y());
    for (double d = c - R + kStep; d <= c + R + 1e-9; d += kStep) {
      const float v = bilinearAt(lin, p.x() + d * n.x(), p.y() + d * n.y());
      if (!std::isfinite(v) || !std::isfinite(prev)) return false;
      g[count] = static_cast<double>(v - prev);
      at[count++] = d - 0.5 * kStep;
      g_max = std::max(g_max, g[count - 1]);
      prev = v;
    }
    double sw = 0, sd = 0;
    for (int k = 0; k < count; ++k) {
      if (g[k] < 0 && g[k] <= -keep_negative * g_max) continue;
      sw += g[k];
      sd += g[k] * at[k];
    }
    if (sw < 0.05) return false;
    const double next = sd / sw;
    if (std::abs(next) > R) return false;
    c = next;
  }
  offset = c;
  return true;
}

// Total least squares line a x + b y = c ((a, b) unit) through >= 2 points.
bool fitLine(const std::vector<Eigen::Vector2d>& points, Eigen::Vector3d& line) {
  if (points.size() < 2) return false;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& q : points) mean += q;
  mean /= static_cast<double>(points.size());
  Eigen::Matrix2d S = Eigen::Matrix2d::Zero();
  for (const auto& q : points) S += (q - mean) * (q - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(S);
  const Eigen::Vector2d normal = eig.eigenvectors().col(0);  // smallest: across the line
  line = Eigen::Vector3d(normal.x(), normal.y(), normal.dot(mean));
  return true;
}

// A tag's edge is clear of other edges for the profile's reach (tracking/detect.cpp sizes it), so
// its step keeps the small negative differences, noise, and drops only a neighbour's steep step
// should one come in reach. On the studio main camera's tag boards (noise sigma 2 sRGB codes),
// positive differences alone put the corners 0.046 px outwards on average (0.011 px without the
// noise) and the camera 1.57 mm from the truth (median of 3 frames, max 2.05 mm); keeping them,
// 0.91 mm (max 1.19 mm), and one camera alone on the prop take 2.28 -> 2.05 mm (median of 63).
// calib's quadtree markers keep 0: their neighbours are close, and 0.25 took the synthetic
// quadtree views' median from 0.065 to 0.110 px.
constexpr double kTagKeepNegative = 0.25;

}  // namespace

float bilinearAt(const cv::Mat& image, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= image.cols || y0 + 1 >= image.rows) return NAN;
  const double fx = x - x0, fy = y - y0;
  const float* r0 = image.ptr<float>(y0);
  const float* r1 = image.ptr<float>(y0 + 1);
  return static_cast<float>((1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
                            fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]));
}

bool intersectLines(const Eigen::Vector3d& l0, const Eigen::Vector3d& l1, Eigen::Vector2d& out) {
  Eigen::Matrix2d A;
  A << l0.x(), l0.y(), l1.x(), l1.y();
  if (std::abs(A.determinant()) < 0.2) return false;  // near parallel: not a corner
  out = A.inverse() * Eigen::Vector2d(l0.z(), l1.z());
  return out.allFinite();
}

bool refineCornerByEdges(const cv::Mat& lin, const MarkerCorner& e, Eigen::Vector2d& out) {
  auto H = [&](const Eigen::Vector2d& b) { return Eigen::Vector2d((e.H * b.homogeneous()).hnormalized()); };
  const double t0_px = 3.0, t1_px = std::min(0.45 * e.edge_px, 16.0);
  if (t1_px - t0_px < 1.5) return false;
  const double R = std::clamp(0.9 * e.profile_half_px, 1.5, 4.0);
  std::array<Eigen::Vector3d, 2> lines;
  for (int side = 0; side < 2; ++side) {
    const Eigen::Vector2d u = e.along[side], outward = -e.along[1 - side];
    std::vector<Eigen::Vector2d> points;
    for (double t = t0_px; t <= t1_px + 1e-9; t += 1.0) {
      const Eigen::Vector2d b = e.corner + (t / e.px_per_unit) * u;
      const Eigen::Vector2d p = H(b);
      const Eigen::Vector2d n = (H(b + outward / e.px_per_unit) - p).normalized();
      double c = 0;
      if (stepOffset(lin, p, n, R, 0.0, c)) points.push_back(p + c * n);
    }
    if (!fitLine(points, lines[side])) return false;
  }
  return intersectLines(lines[0], lines[1], out);
}

bool measureEdgePoints(const cv::Mat& lin, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                       const Eigen::Vector2d& light_side, double reach_px, double margin_px,
                       std::vector<Eigen::Vector2d>& points) {
  points.clear();
  const Eigen::Vector2d ab = b - a;
  const double length = ab.norm();
  if (!(length - 2 * margin_px >= 2.0)) return false;
  const Eigen::Vector2d u = ab / length;
  Eigen::Vector2d n(-u.y(), u.x());
  if (n.dot(light_side) < 0) n = -n;
  const int count = static_cast<int>(std::floor(length - 2 * margin_px)) + 1;  // one a pixel
  const double spacing = (length - 2 * margin_px) / std::max(count - 1, 1);
  for (int k = 0; k < count; ++k) {
    const Eigen::Vector2d p = a + (margin_px + k * spacing) * u;
    double c = 0;
    if (stepOffset(lin, p, n, reach_px, kTagKeepNegative, c)) points.push_back(p + c * n);
  }
  return static_cast<int>(points.size()) >= std::max(2, count / 2);
}

bool fitEdgeLine(const cv::Mat& lin, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                 const Eigen::Vector2d& light_side, double reach_px, double margin_px,
                 Eigen::Vector3d& line) {
  std::vector<Eigen::Vector2d> points;
  return measureEdgePoints(lin, a, b, light_side, reach_px, margin_px, points) && fitLine(points, line);
}

}  // namespace previz
