// Fixtures for the visual hull tests: the studio's true actor mesh rasterized into every camera
// through its true lens (silhouettes and the main camera's true depth, no renderer), and an
// independent reference for the exact visual hull (point test with Camera::project, marched at
// 1 mm along each ray and bisected). Nothing here uses carving's internals.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "carving/hull.h"
#include "core/rig.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace previz::carving::test {

constexpr double kInf = std::numeric_limits<double>::infinity();

// body(i) for i in [0, n), interleaved over the machine's threads (the test targets are not
// built with OpenMP).
template <class F>
void parallelFor(int n, F body) {
  const int threads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (int i = t; i < n; i += threads) body(i);
    });
  for (auto& th : pool) th.join();
}

struct Raster {
  cv::Mat mask;   // CV_8UC1, 255 where a pixel centre lies in a projected triangle
  cv::Mat depth;  // CV_32FC1, z of the nearest triangle at the pixel centre, +inf elsewhere
};

// Projects every vertex with the camera's true distortion and fills each triangle's pixel
// centres (edges inclusive, so neighbouring triangles leave no crack). Triangles are ~1.5 cm,
// 1-3 px: straight image edges and perspective-correct z are exact to far below a pixel.
inline Raster rasterize(const TriangleMesh& mesh, const RigCamera& rc) {
  const Camera& cam = rc.camera;
  const Pose T_cam_world = rc.T_world_cam.inverse();
  std::vector<Eigen::Vector2d> px(mesh.vertices.size());
  std::vector<double> z(mesh.vertices.size());
  std::vector<char> ok(mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3d p = T_cam_world * mesh.vertices[i].cast<double>();
    const auto q = cam.project(p);
    ok[i] = q.has_value();
    if (q) px[i] = *q;
    z[i] = p.z();
  }
  Raster r;
  r.mask = cv::Mat::zeros(cam.height, cam.width, CV_8UC1);
  r.depth = cv::Mat(cam.height, cam.width, CV_32FC1, cv::Scalar(kInf));
  for (const auto& f : mesh.faces) {
    if (!ok[f[0]] || !ok[f[1]] || !ok[f[2]]) continue;
    const Eigen::Vector2d a = px[f[0]], b = px[f[1]], c = px[f[2]];
    const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    if (std::abs(area) < 1e-12) continue;
    const int u0 = std::max(0, static_cast<int>(std::ceil(std::min({a.x(), b.x(), c.x()}))));
    const int u1 = std::min(cam.width - 1, static_cast<int>(std::floor(std::max({a.x(), b.x(), c.x()}))));
    const int v0 = std::max(0, static_cast<int>(std::ceil(std::min({a.y(), b.y(), c.y()}))));
    const int v1 = std::min(cam.height - 1, static_cast<int>(std::floor(std::max({a.y(), b.y(), c.y()}))));
    for (int v = v0; v <= v1; ++v)
      for (int u = u0; u <= u1; ++u) {
        const Eigen::Vector2d p(u, v);
        auto edge = [](const Eigen::Vector2d& s, const Eigen::Vector2d& e, const Eigen::Vector2d& q) {
          return (e - s).x() * (q - s).y() - (e - s).y() * (q - s).x();
        };
        const double w0 = edge(b, c, p) / area, w1 = edge(c, a, p) / area, w2 = edge(a, b, p) / area;
        if (w0 < 0 || w1 < 0 || w2 < 0) continue;
        r.mask.at<std::uint8_t>(v, u) = 255;
        const double inv_z = w0 / z[f[0]] + w1 / z[f[1]] + w2 / z[f[2]];
        float& d = r.depth.at<float>(v, u);
        d = std::min(d, static_cast<float>(1.0 / inv_z));
      }
  }
  return r;
}

// The exact visual hull of a set of silhouettes, by definition: a point is in it when it lies in
// the volume, is seen (Camera::project lands in the image) by at least min_views cameras and
// falls outside the silhouette in at most k of them.
struct ReferenceHull {
  std::vector<RigCamera> cameras;
  std::vector<cv::Mat> masks;  // empty mask = camera not used
  int k = 0, min_views = 2;
  Eigen::AlignedBox3d volume;

  bool inside(const Eigen::Vector3d& p) const {
    if (!volume.contains(p)) return false;
    int outs = 0, views = 0;
    for (size_t c = 0; c < cameras.size(); ++c) {
      if (masks[c].empty()) continue;
      const Camera& cam = cameras[c].camera;
      const auto q = cam.project(cameras[c].T_world_cam.inverse() * p);
      if (!q) continue;
      const int u = static_cast<int>(std::floor(q->x() + 0.5)), v = static_cast<int>(std::floor(q->y() + 0.5));
      if (u < 0 || v < 0 || u >= cam.width || v >= cam.height) continue;
      ++views;
      if (masks[c].at<std::uint8_t>(v, u) <= 127 && ++outs > k) return false;
    }
    return views >= min_views;
  }
};

// Fraction of true actor pixels ('truth' finite) where 'depth' keeps the actor on the right side
// of a virtual plane at distance d in front of (front = true) or behind its true surface
// (issue 5, item 2).
inline double orderedFraction(const cv::Mat& depth, const cv::Mat& truth, double d, bool front) {
  int n = 0, ok = 0;
  for (int v = 0; v < truth.rows; ++v)
    for (int u = 0; u < truth.cols; ++u) {
      const double z = truth.at<float>(v, u);
      if (!std::isfinite(z)) continue;
      const double ours = depth.at<float>(v, u);
      ++n;
      ok += front ? ours > z - d : ours < z + d;
    }
  return double(ok) / n;
}

// A pixel's ray through a camera's true lens: point(t) = origin + t dir with t = camera z.
struct PixelRay {
  Eigen::Vector3d origin, dir;
};
inline std::optional<PixelRay> pixelRay(const RigCamera& rc, int u, int v) {
  const auto d = rc.camera.unproject(Eigen::Vector2d(u, v));
  if (!d) return std::nullopt;
  return PixelRay{rc.T_world_cam.translation(), rc.T_world_cam.linear() * (*d / d->z())};
}

// First point of the reference hull along the ray within [t0, t1]: 1 mm march, then bisection
// to 1 um. +inf when none.
inline double referenceDepth(const ReferenceHull& ref, const PixelRay& ray, double t0, double t1) {
  const double step = 0.001 / ray.dir.norm();
  double prev = t0;
  for (double t = t0; t <= t1; t += step) {
    if (ref.inside(ray.origin + t * ray.dir)) {
      if (t == t0) return t;
      double out = prev, in = t;
      while ((in - out) * ray.dir.norm() > 1e-6) {
        const double mid = 0.5 * (out + in);
        (ref.inside(ray.origin + mid * ray.dir) ? in : out) = mid;
      }
      return 0.5 * (out + in);
    }
    prev = t;
  }
  return kInf;
}

// Ray parameters where the ray crosses a box (empty optional when it misses).
inline std::optional<std::pair<double, double>> rayBox(const PixelRay& ray, const Eigen::AlignedBox3d& box) {
  double t0 = 0, t1 = kInf;
  for (int a = 0; a < 3; ++a) {
    if (ray.dir[a] == 0) {
      if (ray.origin[a] < box.min()[a] || ray.origin[a] > box.max()[a]) return std::nullopt;
      continue;
    }
    double ta = (box.min()[a] - ray.origin[a]) / ray.dir[a], tb = (box.max()[a] - ray.origin[a]) / ray.dir[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t0 <= t1)) return std::nullopt;
  return std::make_pair(t0, t1);
}

// The studio at one instant: rig (witnesses at full size, main at main_w x main_h on its dolly
// pose), the true actor mesh and its rasterized silhouettes.
struct StudioFrame {
  double time_s = 4.0;
  std::vector<RigCamera> witnesses;
  RigCamera main;
  TriangleMesh actor;
  Eigen::AlignedBox3d actor_bounds;
  std::vector<cv::Mat> masks;  // one per witness
  Raster main_raster;
};

// undistorted: every lens made ideal; witness_lens: every witness given this distortion;
// witness_cameras: the studio rig's witness count (synth::StudioRigOptions).
inline StudioFrame makeStudioFrame(double time_s, int main_w, int main_h, bool undistorted = false,
                                   const Distortion* witness_lens = nullptr,
                                   int witness_cameras = 8, int fisheye_witnesses = 0) {
  StudioFrame f;
  f.time_s = time_s;
  const synth::StudioConfig config;
  const synth::Studio studio(config);
  synth::StudioRigOptions rig_options;
  rig_options.main_width = main_w;
  rig_options.main_height = main_h;
  rig_options.witness_cameras = witness_cameras;
  rig_options.fisheye_witnesses = fisheye_witnesses;
  const Rig rig = synth::studioRig(rig_options, config.take_duration_s, true);
  for (const RigCamera& rc : rig.cameras) {
    RigCamera c = rc;
    if (undistorted) c.camera.dist = Distortion{};
    if (witness_lens && c.role != "main") c.camera.dist = *witness_lens;
    if (c.role == "main") {
      c.T_world_cam = synth::mainCameraPose(time_s, config.take_duration_s, true);
      f.main = c;
    } else {
      f.witnesses.push_back(c);
    }
  }
  f.actor = studio.actorMesh(time_s);
  f.actor_bounds = studio.actorBounds(time_s);
  f.masks.resize(f.witnesses.size());
  parallelFor(static_cast<int>(f.witnesses.size()),
              [&](int c) { f.masks[c] = rasterize(f.actor, f.witnesses[c]).mask; });
  f.main_raster = rasterize(f.actor, f.main);
  return f;
}

// Per-pixel reference depth of the exact hull for every pixel of 'mask' (+inf where the ray
// misses it), marching over the actor's bounds grown by 'margin_m'.
inline cv::Mat referenceDepthMap(const ReferenceHull& ref, const RigCamera& main, const cv::Mat& mask,
                                 const Eigen::AlignedBox3d& search_box) {
  cv::Mat out(mask.size(), CV_32FC1, cv::Scalar(kInf));
  parallelFor(mask.rows, [&](int v) {
    for (int u = 0; u < mask.cols; ++u) {
      if (mask.at<std::uint8_t>(v, u) <= 127) continue;
      const auto ray = pixelRay(main, u, v);
      if (!ray) continue;
      const auto span = rayBox(*ray, search_box);
      if (!span) continue;
      out.at<float>(v, u) = static_cast<float>(referenceDepth(ref, *ray, span->first, span->second));
    }
  });
  return out;
}

inline double percentile(std::vector<double> v, double q) {
  if (v.empty()) return kInf;
  const size_t i = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + i, v.end());
  return v[i];
}

struct DepthErrors {
  std::vector<double> abs;  // |depth - reference| per pixel (+inf where exactly one is finite)
  int both_finite = 0, only_ours = 0, only_ref = 0;
  double median() const { return percentile(abs, 0.5); }
  double p(double q) const { return percentile(abs, q); }
};

// Compares two depth maps over the pixels of 'mask' where at least one is finite.
inline DepthErrors compareDepth(const cv::Mat& ours, const cv::Mat& ref, const cv::Mat& mask) {
  DepthErrors e;
  for (int v = 0; v < mask.rows; ++v)
    for (int u = 0; u < mask.cols; ++u) {
      if (mask.at<std::uint8_t>(v, u) <= 127) continue;
      const double a = ours.at<float>(v, u), b = ref.at<float>(v, u);
      const bool fa = std::isfinite(a), fb = std::isfinite(b);
      if (!fa && !fb) continue;
      if (fa && fb) {
        ++e.both_finite;
        e.abs.push_back(std::abs(a - b));
      } else {
        (fa ? e.only_ours : e.only_ref) += 1;
        e.abs.push_back(kInf);
      }
    }
  return e;
}

inline void printErrors(const char* what, const DepthErrors& e) {
  std::printf("%s: pixels %zu (both finite %d, only ours %d, only reference %d): median %.2f mm, "
              "p90 %.2f mm, p95 %.2f mm, p99 %.2f mm\n",
              what, e.abs.size(), e.both_finite, e.only_ours, e.only_ref, 1e3 * e.median(),
              1e3 * e.p(0.90), 1e3 * e.p(0.95), 1e3 * e.p(0.99));
}

}  // namespace previz::carving::test
