// Depth for any camera from a carved hull: each pixel's ray walks the kept cells and finds the
// first hull point, below the voxel size (carving/hull.h, Carver::depth).
#include "carving/hull.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "carving/detail/carver_impl.h"
#include "carving/detail/hull_camera.h"
#include "carving/detail/hull_data.h"
#include "core/error.h"
#include "core/simd.h"
#include "core/threads.h"

namespace previz::carving {

using detail::CameraModel;
using detail::CamState;
using detail::FrameCam;
using detail::HullData;
using detail::RayTable;
using detail::kRefineIterations;
using detail::kSamplesPerVoxel;

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}  // namespace

// ---------------------------------------------------------------------------------------------
// Depth: first hull surface along each pixel's ray
// ---------------------------------------------------------------------------------------------
namespace {

// Amanatides & Woo (1987) traversal of a grid of unit cells, p(t) = p0 + t dir.
struct Dda {
  int i[3], step[3];
  double t_max[3], t_delta[3];
  void init(const double* p0, const double* dir, double t, const int* lo, const int* hi) {
    for (int a = 0; a < 3; ++a) {
      const double p = p0[a] + t * dir[a];
      const int c = std::clamp(detail::floorToInt(std::clamp(p, -1e7, 1e7)), lo[a], hi[a] - 1);
      i[a] = c;
      if (dir[a] > 0) {
        step[a] = 1;
        t_delta[a] = 1.0 / dir[a];
        t_max[a] = (c + 1 - p0[a]) / dir[a];
      } else if (dir[a] < 0) {
        step[a] = -1;
        t_delta[a] = -1.0 / dir[a];
        t_max[a] = (c - p0[a]) / dir[a];
      } else {
        step[a] = 0;
        t_delta[a] = kInf;
        t_max[a] = kInf;
      }
    }
  }
  double exitT() const { return std::min(t_max[0], std::min(t_max[1], t_max[2])); }
  // Steps into the next cell; false when it leaves [lo, hi).
  bool advance(const int* lo, const int* hi) {
    const int a = t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2)
                                      : (t_max[1] < t_max[2] ? 1 : 2);
    i[a] += step[a];
    t_max[a] += t_delta[a];
    return i[a] >= lo[a] && i[a] < hi[a];
  }
};

// kWords: words per camera set, 0 = h->set_words (see traceRays).
template <int kWords>
struct RayQuery {
  const HullData* h;
  double o[3], d[3];  // world: point(t) = o + t d, t = depth along the camera's axis
  double go[3], gd[3];  // the same in finest-voxel units from the grid origin
  double step_t;        // sampling step inside surface voxels, in t
  // The ray in each witness camera's frame, q(t) = qo + t qd (camera c at 3 c): qo per call,
  // qd per pixel and camera on first use (camera set qd_valid). Per-thread scratch, sized for
  // the rig once per call.
  const double* qo = nullptr;
  mutable std::vector<double> qd;
  mutable std::vector<std::uint64_t> qd_valid;

  RayQuery(const HullData& hull, const double* qo_cams)
      : h(&hull), qo(qo_cams), qd(3 * hull.cameras->size()), qd_valid(hull.set_words) {}

  int words() const { return kWords > 0 ? kWords : h->set_words; }
  void setDirection(const Eigen::Vector3d& dir) {
    for (int a = 0; a < 3; ++a) {
      d[a] = dir[a];
      gd[a] = dir[a] / h->voxel;
    }
    std::fill_n(qd_valid.data(), words(), std::uint64_t{0});
  }
  // Camera c's verdict on the ray's point at t (c's ray direction computed on first use).
  [[gnu::always_inline]] CamState stateAt(int c, double t) const {
    const int w = c / detail::kCamerasPerWord, bit = c % detail::kCamerasPerWord;
    const CameraModel& cam = (*h->cameras)[c];
    double* qdc = qd.data() + 3 * c;
    const double* qoc = qo + 3 * c;
    if (!((qd_valid[w] >> bit) & 1)) {
      qdc[0] = cam.R[0] * d[0] + cam.R[1] * d[1] + cam.R[2] * d[2];
      qdc[1] = cam.R[3] * d[0] + cam.R[4] * d[1] + cam.R[5] * d[2];
      qdc[2] = cam.R[6] * d[0] + cam.R[7] * d[1] + cam.R[8] * d[2];
      qd_valid[w] |= std::uint64_t{1} << bit;
    }
    const double q[3] = {qoc[0] + t * qdc[0], qoc[1] + t * qdc[1], qoc[2] + t * qdc[2]};
    return detail::cameraPointState(cam, h->frames[c], q);
  }

  // The camera whose verdict last put a point outside (-1: none yet). Kept from sample to sample
  // and from ray to ray (a thread's rays are neighbouring pixels): the point just outside the
  // hull is most often outside the same camera's silhouette as the one before (88 % of the
  // outside verdicts on the live bench take), so it is asked first, and the others are not
  // asked at all. The verdict does not depend on the order the cameras are asked in.
  mutable int last_out = -1;

  // The k-of-n rule at o + t d, as HullData::insideGiven, with the camera coordinates
  // interpolated along the ray.
  [[gnu::always_inline]] bool insideAt(double t, const detail::SurfaceInfo& info,
                                       const std::uint64_t* mixed) const {
    int n_out = info.n_out, views = info.n_out + info.n_in;
    if (n_out > h->k) return false;
    // Counts camera c's verdict; false once the point is out of more than k cameras.
    const auto count = [&](int c) __attribute__((always_inline)) {
      const CamState s = stateAt(c, t);
      if (s == detail::kOut) {
        ++views;
        if (++n_out > h->k) {
          last_out = c;
          return false;
        }
      } else if (s == detail::kIn) {
        ++views;
      }
      return true;
    };
    int first = -1;
    if (last_out >= 0 &&
        ((mixed[last_out / detail::kCamerasPerWord] >> (last_out % detail::kCamerasPerWord)) & 1)) {
      first = last_out;
      if (!count(first)) return false;
    }
    for (int w = 0; w < words(); ++w) {
      for (std::uint64_t bits = mixed[w]; bits; bits &= bits - 1) {
        const int c = w * detail::kCamerasPerWord + __builtin_ctzll(bits);
        if (c != first && !count(c)) return false;
      }
    }
    return views >= h->min_views;
  }

  // Where the ray enters the hull between t_out (outside) and t_in (inside), k = 0, without
  // bisection: in each undecided camera that sees t_out outside, the ray's image moves from an
  // outside pixel into a neighbouring inside one and crosses their shared edge at a fraction s
  // of the way (the image of a sub-voxel segment is straight to far below a pixel); the hull
  // starts where the last camera lets it in. False (bisect instead) when some camera's image
  // jumps diagonally or by more than a pixel, leaves the image, or k > 0.
  [[gnu::always_inline]] bool crossing(const std::uint64_t* mixed, double t_out, double t_in,
                                       double* hit) const {
    if (h->k != 0) return false;
    double t_hit = t_out;
    for (int w = 0; w < words(); ++w) {
      for (std::uint64_t bits = mixed[w]; bits; bits &= bits - 1) {
        const int c = w * detail::kCamerasPerWord + __builtin_ctzll(bits);
        const CameraModel& cam = (*h->cameras)[c];
        const detail::FrameCam& frame = h->frames[c];
        const double* qdc = qd.data() + 3 * c;
        const double* qoc = qo + 3 * c;
        const double qa[3] = {qoc[0] + t_out * qdc[0], qoc[1] + t_out * qdc[1],
                              qoc[2] + t_out * qdc[2]};
        const double qb[3] = {qoc[0] + t_in * qdc[0], qoc[1] + t_in * qdc[1],
                              qoc[2] + t_in * qdc[2]};
        double ua, va, ub, vb;
        if (!cam.project(qa, ua, va) || !cam.project(qb, ub, vb)) return false;
        const int iua = detail::floorToInt(ua + 0.5), iva = detail::floorToInt(va + 0.5);
        const int iub = detail::floorToInt(ub + 0.5), ivb = detail::floorToInt(vb + 0.5);
        if (iua < 0 || iva < 0 || iub < 0 || ivb < 0 || iua >= cam.width || iub >= cam.width ||
            iva >= cam.height || ivb >= cam.height)
          return false;
        if (frame.insidePixel(iua, iva)) continue;  // already inside at t_out
        double s;
        if (iva == ivb && std::abs(iua - iub) == 1)
          s = (0.5 * (iua + iub) - ua) / (ub - ua);
        else if (iua == iub && std::abs(iva - ivb) == 1)
          s = (0.5 * (iva + ivb) - va) / (vb - va);
        else
          return false;
        t_hit = std::max(t_hit, t_out + std::clamp(s, 0.0, 1.0) * (t_in - t_out));
      }
    }
    *hit = t_hit;
    return true;
  }

  // The hull's first point in a surface voxel's segment [ta, tb] (ta known outside): samples
  // at step_t, then bisection between the last outside and the first inside sample.
  [[gnu::always_inline]] bool searchVoxel(std::int64_t surface_index, double ta, double tb,
                                          double* hit) const {
    const detail::SurfaceInfo& info = h->surface_info[surface_index];
    const std::uint64_t* mixed = h->surfaceMixed(surface_index);
    const int n = std::max(1, static_cast<int>(std::ceil((tb - ta) / step_t)));
    const double step = (tb - ta) / n;
    double prev = ta;
    for (int s = 1; s <= n; ++s) {
      const double t = s == n ? tb : ta + s * step;
      if (insideAt(t, info, mixed)) {
        if (crossing(mixed, prev, t, hit)) return true;
        double out = prev, in = t;
        for (int it = 0; it < kRefineIterations; ++it) {
          const double mid = 0.5 * (out + in);
          (insideAt(mid, info, mixed) ? in : out) = mid;
        }
        *hit = 0.5 * (out + in);
        return true;
      }
      prev = t;
    }
    return false;
  }

  // Walks the voxels of a mixed brick over [ta, tb].
  [[gnu::always_inline]] bool searchBrick(const detail::Brick& brick, const int* brick_cell,
                                          double ta, double tb, double* hit) const {
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = (brick_cell[a] + h->brick_min[a]) << detail::kBrickShift;
      hi[a] = lo[a] + detail::kBrickEdge;
    }
    Dda dda;
    dda.init(go, gd, ta, lo, hi);
    double t = ta;
    while (t < tb) {
      const double te = std::min(dda.exitT(), tb);
      if (te > t) {
        const int bit = ((dda.i[2] & 3) << 4) | ((dda.i[1] & 3) << 2) | (dda.i[0] & 3);
        const std::uint64_t m = std::uint64_t{1} << bit;
        if (brick.inside & m) {
          *hit = t;
          return true;
        }
        if (brick.surface & m) {
          const std::uint32_t idx = brick.offset + __builtin_popcountll(brick.surface & (m - 1));
          if (searchVoxel(idx, t, te, hit)) return true;
        }
        t = te;
      }
      if (!dda.advance(lo, hi)) break;
    }
    return false;
  }

  // Depth (t) of the first hull point along the ray at or beyond t_start; +inf when it misses.
  // run, searchBrick, searchVoxel, insideAt (and its lambda), stateAt and crossing are inlined
  // by force into traceRays: in traceRays' PREVIZ_WIDE versions GCC no longer inlined them on
  // its own, and the AVX2 version called the baseline code.
  [[gnu::always_inline]] double run(double t_start) const {
    double t0 = t_start, t1 = kInf;
    int lo[3] = {0, 0, 0}, hi[3];
    double bo[3], bd[3];
    for (int a = 0; a < 3; ++a) {
      hi[a] = h->brick_dims[a];
      bo[a] = go[a] / detail::kBrickEdge - h->brick_min[a];
      bd[a] = gd[a] / detail::kBrickEdge;
      if (bd[a] == 0.0) {
        if (bo[a] < 0 || bo[a] > hi[a]) return kInf;
        continue;
      }
      double ta = -bo[a] / bd[a], tb = (hi[a] - bo[a]) / bd[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (!(t0 < t1)) return kInf;
    Dda dda;
    dda.init(bo, bd, t0, lo, hi);
    double t = t0;
    while (t < t1) {
      const double te = std::min(dda.exitT(), t1);
      if (te > t) {
        const std::int32_t b =
            h->brick_index[(static_cast<size_t>(dda.i[2]) * hi[1] + dda.i[1]) * hi[0] + dda.i[0]];
        if (b == detail::kBrickFull) return t;
        double hit;
        if (b >= 0 && searchBrick(h->bricks[b], dda.i, t, te, &hit)) return hit;
        t = te;
      }
      if (!dda.advance(lo, hi)) break;
    }
    return kInf;
  }
};

}  // namespace

namespace {

constexpr int kBoundShift = 2;  // the depth lower bound is kept per 4 x 4 pixels

// A lower bound of the hull's depth per 4 x 4 pixel block of the camera: super-bricks (4^3
// bricks) that hold any kept cell, projected (8 corners, distortion pad) with the nearest
// corner's depth. Every hull point seen at a pixel lies in such a super-brick whose footprint
// covers the pixel, so no ray starts past its first hull point; +inf blocks see no hull at
// all. Returns false when some super-brick is not wholly in front of the camera (no bound).
bool depthLowerBound(const HullData& h, const CameraModel& cam, cv::Mat& bound) {
  const int w = (cam.width + 3) >> kBoundShift, ht = (cam.height + 3) >> kBoundShift;
  bound.create(ht, w, CV_32FC1);
  bound.setTo(cv::Scalar(std::numeric_limits<float>::infinity()));
  constexpr int kGroup = 4;  // bricks per super-brick edge
  const Eigen::Vector3i bd = h.brick_dims;
  const Eigen::Vector3i sd = (bd.array() + kGroup - 1) / kGroup;
  std::vector<std::uint8_t> occupied(static_cast<size_t>(sd.x()) * sd.y() * sd.z(), 0);
  for (int z = 0; z < bd.z(); ++z)
    for (int y = 0; y < bd.y(); ++y)
      for (int x = 0; x < bd.x(); ++x)
        if (h.brick_index[(static_cast<size_t>(z) * bd.y() + y) * bd.x() + x] !=
            detail::kBrickEmpty)
          occupied[(static_cast<size_t>(z / kGroup) * sd.y() + y / kGroup) * sd.x() + x / kGroup] = 1;
  const double edge = h.voxel * detail::kBrickEdge * kGroup;
  const Eigen::Vector3d base =
      h.origin + h.voxel * detail::kBrickEdge * h.brick_min.cast<double>();
  for (int z = 0; z < sd.z(); ++z)
    for (int y = 0; y < sd.y(); ++y)
      for (int x = 0; x < sd.x(); ++x) {
        if (!occupied[(static_cast<size_t>(z) * sd.y() + y) * sd.x() + x]) continue;
        double umin = kInf, umax = -kInf, vmin = kInf, vmax = -kInf, z_near = kInf;
        double xmin = kInf, xmax = -kInf, ymin = kInf, ymax = -kInf;
        for (int c = 0; c < 8; ++c) {
          const Eigen::Vector3d p =
              base + edge * Eigen::Vector3d(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2));
          double q[3], u, v;
          cam.toCamera(p.data(), q);
          if (!cam.project(q, u, v)) return false;
          z_near = std::min(z_near, q[2]);
          umin = std::min(umin, u);
          umax = std::max(umax, u);
          vmin = std::min(vmin, v);
          vmax = std::max(vmax, v);
          xmin = std::min(xmin, q[0] / q[2]);
          xmax = std::max(xmax, q[0] / q[2]);
          ymin = std::min(ymin, q[1] / q[2]);
          ymax = std::max(ymax, q[1] / q[2]);
        }
        const double dx = xmax - xmin, dy = ymax - ymin;
        const double pad = cam.pad_per_diam2 * (dx * dx + dy * dy) + 1.0;
        const int u0 = std::max(0, detail::floorToInt(std::max(umin - pad, -1e7) + 0.5));
        const int u1 = std::min(cam.width - 1, detail::floorToInt(std::min(umax + pad, 1e7) + 0.5));
        const int v0 = std::max(0, detail::floorToInt(std::max(vmin - pad, -1e7) + 0.5));
        const int v1 = std::min(cam.height - 1, detail::floorToInt(std::min(vmax + pad, 1e7) + 0.5));
        const float zf = static_cast<float>(z_near);
        for (int bv = v0 >> kBoundShift; bv <= v1 >> kBoundShift && v0 <= v1; ++bv) {
          float* row = bound.ptr<float>(bv);
          for (int bu = u0 >> kBoundShift; bu <= u1 >> kBoundShift && u0 <= u1; ++bu)
            row[bu] = std::min(row[bu], zf);
        }
      }
  return true;
}

// Every pixel's depth (rows of out), one RayQuery per thread. Rigs of up to 64 cameras (the
// live ones) run with kWords = 1, where the camera-set loops compile away: with the word count
// read at run time the 8-camera depth took 4-6 % longer. Larger rigs run with kWords = 0.
// bound: depthLowerBound's (nullptr: none). sample_m: the sampling step inside surface cells.
template <int kWords>
PREVIZ_WIDE
void traceRays(const HullData& h, const Camera& cam, const RayTable& table,
               const Eigen::Matrix3d& R, const Eigen::Vector3d& centre, const double* qo,
               const cv::Mat& silhouette, const cv::Mat* bound, double sample_m, int threads, cv::Mat& out) {
#pragma omp parallel num_threads(threads)
  {
    RayQuery<kWords> q(h, qo);
    for (int a = 0; a < 3; ++a) {
      q.o[a] = centre[a];
      q.go[a] = (centre[a] - h.origin[a]) / h.voxel;
    }
#pragma omp for schedule(dynamic, 4)
    for (int v = 0; v < cam.height; ++v) {
      float* row = out.ptr<float>(v);
      std::fill(row, row + cam.width, std::numeric_limits<float>::infinity());
      const std::uint8_t* sil = silhouette.empty() ? nullptr : silhouette.ptr<std::uint8_t>(v);
      const float* xy = table.xy.data() + 2 * static_cast<size_t>(v) * cam.width;
      const float* lower = bound ? bound->ptr<float>(v >> kBoundShift) : nullptr;
      for (int u = 0; u < cam.width; ++u) {
        if (sil) {
          // Eight pixels at a time off the silhouette (most of the frame): none has its high bit.
          if (u + 8 <= cam.width) {
            std::uint64_t word;
            std::memcpy(&word, sil + u, sizeof word);
            if ((word & 0x8080808080808080ull) == 0) {
              u += 7;
              continue;
            }
          }
          if (sil[u] <= 127) continue;
        }
        const double t_start = lower ? lower[u >> kBoundShift] : 0.0;
        if (t_start == kInf) continue;  // no hull near this pixel's ray
        const float x = xy[2 * u], y = xy[2 * u + 1];
        if (std::isnan(x)) continue;
        const Eigen::Vector3d d = R * Eigen::Vector3d(x, y, 1.0);
        q.setDirection(d);
        q.step_t = sample_m / d.norm();
        row[u] = static_cast<float>(q.run(t_start));
      }
    }
  }
}

}  // namespace

cv::Mat Carver::depth(const VisualHull& hull, const RigCamera& camera,
                      const cv::Mat& silhouette) const {
  cv::Mat out;
  depth(hull, camera, silhouette, out);
  return out;
}

void Carver::depth(const VisualHull& hull, const RigCamera& camera, const cv::Mat& silhouette,
                   cv::Mat& out) const {
  const Camera& cam = camera.camera;
  cam.validate();
  if (!silhouette.empty()) {
    if (silhouette.type() != CV_8UC1)
      throw Error("depth: silhouette must be 8-bit single-channel",
                  ErrorContext{"", cam.name, std::nullopt, "silhouette"});
    if (silhouette.cols != cam.width || silhouette.rows != cam.height)
      throw Error("depth: silhouette is " + std::to_string(silhouette.cols) + "x" +
                      std::to_string(silhouette.rows) + " but the camera is " +
                      std::to_string(cam.width) + "x" + std::to_string(cam.height),
                  ErrorContext{"", cam.name, std::nullopt, "silhouette"});
  }
  out.create(cam.height, cam.width, CV_32FC1);
  if (!hull.data || !hull.data->hasCells()) {
    out.setTo(cv::Scalar(std::numeric_limits<float>::infinity()));
    return;
  }
  const int threads = resolveThreads(impl_->options.threads);
  const std::shared_ptr<const RayTable> table = impl_->rayTable(cam, threads);
  const HullData& h = *hull.data;
  CameraModel model = table->model;
  {
    const Pose T_cam_world = camera.T_world_cam.inverse();
    for (int r = 0; r < 3; ++r) {
      for (int col = 0; col < 3; ++col) model.R[r * 3 + col] = T_cam_world.linear()(r, col);
      model.t[r] = T_cam_world.translation()[r];
    }
  }
  cv::Mat bound;
  const bool bounded = depthLowerBound(h, model, bound);
  const Eigen::Matrix3d R = camera.T_world_cam.linear();
  const Eigen::Vector3d centre = camera.T_world_cam.translation();
  // The camera centre in every witness camera's frame (the rays' common origin there).
  std::vector<double> qo(3 * h.cameras->size());
  for (size_t c = 0; c < h.cameras->size(); ++c)
    (*h.cameras)[c].toCamera(centre.data(), qo.data() + 3 * c);
  const double step = impl_->options.depth_step_m;
  const double sample_m = step > 0 ? step : h.voxel / kSamplesPerVoxel;
  if (h.set_words == 1)
    traceRays<1>(h, cam, *table, R, centre, qo.data(), silhouette, bounded ? &bound : nullptr,
                 sample_m, threads, out);
  else
    traceRays<0>(h, cam, *table, R, centre, qo.data(), silhouette, bounded ? &bound : nullptr,
                 sample_m, threads, out);
}

}  // namespace previz::carving
