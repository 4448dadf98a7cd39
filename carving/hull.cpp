// Visual hull: coarse-to-fine carving of a sparse cell hierarchy and the exact point test (the
// per-pixel hull depth for any camera is in hull_depth.cpp, the surface mesh in hull_mesh.cpp).
// See carving/hull.h for the contract and carving/detail/hull_camera.h for the projection and
// the footprint test.
//
// Carving. Level l cells have edge voxel * 2^l. Top cells (~32 cm) start with every used camera
// undecided. A parent that is undecided ("mixed") is split into its 8 children, and each child
// is tested only in the cameras that were still mixed for its parent: a camera that saw the
// parent wholly inside (or wholly outside, or not at all) says the same of every child. Small
// parents are projected once per camera with their Jacobian (affine footprints plus a bound on
// the second-order term); large ones project the 27 lattice corners of their 8 children, each
// footprint padded by the bound on the distortion's curvature. Children outside in more
// than k cameras, or seen by fewer than min_views, are dropped; children inside in every camera
// that sees them are kept whole; the rest go one level down, and at level 0 become surface
// voxels that keep their undecided cameras for the exact point test. The work follows the
// surface: the cells tested at each level are those next to the silhouette cones' boundary.
#include "carving/hull.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>

#include <opencv2/imgproc.hpp>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "carving/detail/carver_impl.h"
#include "carving/detail/hull_camera.h"
#include "carving/detail/hull_data.h"
#include "core/error.h"
#include "core/simd.h"
#include "core/stopwatch.h"
#include "core/threads.h"

namespace previz::carving {

using detail::CameraModel;
using detail::CamState;
using detail::FrameCam;
using detail::HullData;
using detail::BlockOut;
using detail::Cell;
using detail::Grid;
using detail::RayTable;
using detail::kRefineIterations;
using detail::kSamplesPerVoxel;

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kTopCellsPerAxis = 16;  // the top level has at most this many cells per axis

std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

}  // namespace

void HullOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& message) {
    throw Error("carve: " + field + " " + message, fieldContext(field));
  };
  if (!(voxel_m > 0.0) || !std::isfinite(voxel_m))
    bad("voxel_m", "must be a finite value > 0 (got " + num(voxel_m) + ")");
  const Eigen::Vector3d size = volume.sizes();
  if (volume.isEmpty() || !(size.minCoeff() > 0.0) || !size.allFinite())
    bad("volume", "must be a non-empty finite box");
  if (size.maxCoeff() / voxel_m > 65000)
    bad("voxel_m", "gives more than 65000 cells along an axis of the volume (got " +
                       num(voxel_m) + ")");
  if (!(depth_step_m >= 0.0) || !std::isfinite(depth_step_m))
    bad("depth_step_m", "must be a finite value >= 0 (got " + num(depth_step_m) + ")");
  if (k < 0) bad("k", "must be >= 0 (got " + std::to_string(k) + ")");
  if (min_views < 1) bad("min_views", "must be >= 1 (got " + std::to_string(min_views) + ")");
  if (threads < 0) bad("threads", "must be >= 0 (got " + std::to_string(threads) + ")");
}

// ---------------------------------------------------------------------------------------------
// Cameras and silhouettes
// ---------------------------------------------------------------------------------------------
namespace detail {
namespace {

// Bounds over the disc |x| <= radius (ideal normalized) of the distortion's first and second
// derivatives (operator norms, via Frobenius norms), sampled on a polar grid by central
// differences. The distortion is a smooth low-degree polynomial, so its derivatives vary slowly;
// the 1.25 covers the sampling.
struct LensBounds {
  double jacobian = 1;  // sup |D distort|
  double second = 0;    // sup |D^2 distort [h, h]| / |h|^2
};
LensBounds lensBounds(const Camera& camera, double radius) {
  const double h = 1e-3 * std::max(radius, 0.1);
  auto f = [&](double x, double y) { return camera.distort(Eigen::Vector2d(x, y)); };
  LensBounds b{0, 0};
  for (int ir = 0; ir <= 48; ++ir) {
    const double r = radius * ir / 48.0;
    for (int ia = 0; ia < 96; ++ia) {
      const double a = 2.0 * M_PI * ia / 96.0;
      const double x = r * std::cos(a), y = r * std::sin(a);
      b.jacobian = std::max(b.jacobian, camera.distortJacobian(Eigen::Vector2d(x, y)).norm());
      const Eigen::Vector2d fxx = (f(x + h, y) - 2.0 * f(x, y) + f(x - h, y)) / (h * h);
      const Eigen::Vector2d fyy = (f(x, y + h) - 2.0 * f(x, y) + f(x, y - h)) / (h * h);
      const Eigen::Vector2d fxy =
          (f(x + h, y + h) - f(x + h, y - h) - f(x - h, y + h) + f(x - h, y - h)) / (4 * h * h);
      const double n2 = fxx.squaredNorm() + fyy.squaredNorm() + 2.0 * fxy.squaredNorm();
      b.second = std::max(b.second, std::sqrt(n2));
    }
  }
  b.jacobian *= 1.25;
  b.second *= 1.25;
  return b;
}

// Largest ideal normalized radius that the image border undistorts to (+inf when some border
// pixel has no preimage in the lens' invertible domain).
double borderRadius(const Camera& camera) {
  const InverseDistortion inverse(camera.dist);
  double worst = 0;
  auto visit = [&](double u, double v) {
    const Eigen::Vector2d xd = camera.pixelToNormalized(Eigen::Vector2d(u, v));
    Eigen::Vector2d x = xd;
    if (!camera.dist.isZero()) {
      const InverseResult r = inverse.solve(xd);
      if (!r.ok()) {
        worst = kInf;
        return;
      }
      x = r.point;
    }
    worst = std::max(worst, x.norm());
  };
  const double u_max = camera.width - 0.5, v_max = camera.height - 0.5;
  for (double u = -0.5; u < u_max + 2.0; u += 2.0) {
    visit(std::min(u, u_max), -0.5);
    visit(std::min(u, u_max), v_max);
  }
  for (double v = -0.5; v < v_max + 2.0; v += 2.0) {
    visit(-0.5, std::min(v, v_max));
    visit(u_max, std::min(v, v_max));
  }
  return worst;
}

}  // namespace

CameraModel makeCameraModel(const RigCamera& rig_camera) {
  const Camera& c = rig_camera.camera;
  c.validate();
  CameraModel m;
  m.name = c.name;
  m.width = c.width;
  m.height = c.height;
  const Pose T_cam_world = rig_camera.T_world_cam.inverse();
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) m.R[r * 3 + col] = T_cam_world.linear()(r, col);
    m.t[r] = T_cam_world.translation()[r];
  }
  m.centre_world = rig_camera.T_world_cam.translation();
  m.fx = c.fx;
  m.fy = c.fy;
  m.cx = c.cx;
  m.cy = c.cy;
  m.skew = c.skew;
  m.k1 = c.dist.k1;
  m.k2 = c.dist.k2;
  m.p1 = c.dist.p1;
  m.p2 = c.dist.p2;
  m.k3 = c.dist.k3;
  m.k4 = c.dist.k4;
  m.k5 = c.dist.k5;
  m.k6 = c.dist.k6;
  m.kannala_brandt = c.dist.model == LensModel::kKannalaBrandt;
  m.rational = c.dist.isRational();
  m.distorted = !c.dist.isZero();
  // 2 % beyond the border: the valid disc must contain every point that lands in the image.
  const double fold = 0.98 * c.maxInvertibleRadius();  // +inf when the lens never folds
  const double border = borderRadius(c);
  double r_valid = std::min(1.02 * border + 1e-9, fold);
  if (!std::isfinite(r_valid)) {
    throw Error("carve: the image border has no ray through this lens (distortion folds "
                "before the image edge)",
                ErrorContext{"", c.name, std::nullopt, "distortion"});
  }
  m.r_valid = r_valid;
  m.r2_valid = r_valid * r_valid;
  const double lk = std::max(std::hypot(c.fx, c.skew), c.fy);  // |K| on normalized coordinates
  const LensBounds lens = m.distorted ? lensBounds(c, r_valid) : LensBounds{1.0, 0.0};
  m.pad_per_diam2 = 0.5 * lens.second * lk;
  // Perspective pi(q) = (qx, qy) / qz: |D pi h| <= |h| (1 + r) / z and
  // |D^2 pi [h, h]| <= 2 |h|^2 (1 + r) / z^2 with r the ideal radius; the chain rule through
  // the distortion and K and Taylor's remainder (factor 1/2) give the bound.
  const double s = 1.0 + r_valid;
  m.pad_per_h2 = 0.5 * lk * (2.0 * lens.jacobian * s + lens.second * s * s);
  return m;
}

PREVIZ_WIDE
FrameCam makeFrameCam(const cv::Mat& mask) {
  FrameCam f;
  f.used = true;
  f.width = mask.cols;
  f.height = mask.rows;
  // > 127 is a byte's high bit. One pass ORs every row into a column accumulator and into a
  // per-row flag (16 pixels per SSE2 instruction); the bbox falls out of both.
  std::vector<std::uint8_t> columns(mask.cols, 0);
  int y0 = mask.rows, y1 = -1;
  for (int v = 0; v < mask.rows; ++v) {
    const std::uint8_t* row = mask.ptr<std::uint8_t>(v);
    std::uint8_t* col = columns.data();
    int u = 0;
    std::uint8_t acc = 0;
#ifdef __SSE2__
    __m128i acc16 = _mm_setzero_si128();
    for (; u + 16 <= mask.cols; u += 16) {
      const __m128i x = _mm_loadu_si128(reinterpret_cast<const __m128i*>(row + u));
      acc16 = _mm_or_si128(acc16, x);
      __m128i* c = reinterpret_cast<__m128i*>(col + u);
      _mm_storeu_si128(c, _mm_or_si128(_mm_loadu_si128(c), x));
    }
    acc = _mm_movemask_epi8(acc16) ? 0x80 : 0;
#endif
    for (; u < mask.cols; ++u) {
      acc |= row[u];
      col[u] |= row[u];
    }
    if (acc & 0x80) {
      y0 = std::min(y0, v);
      y1 = v;
    }
  }
  if (y1 < 0) return f;  // nothing inside: every seen point is outside
  int x0 = 0, x1 = mask.cols - 1;
  while (!(columns[x0] & 0x80)) ++x0;
  while (!(columns[x1] & 0x80)) --x1;
  f.x0 = x0;
  f.x1 = x1;
  f.y0 = y0;
  f.y1 = y1;
  const int w = x1 - x0 + 1, h = y1 - y0 + 1;
  // Bit-packed rows. Pixels right of x1 are outside (high bit clear), so whole 16-pixel chunks
  // may run past the bbox as long as they stay in the image row.
  f.stride = (w + 7) / 8 + 8;
  f.bits.assign(static_cast<size_t>(f.stride) * h, 0);
  for (int r = 0; r < h; ++r) {
    const std::uint8_t* row = mask.ptr<std::uint8_t>(y0 + r) + x0;
    std::uint8_t* out = f.bits.data() + static_cast<size_t>(r) * f.stride;
    int c = 0;
#ifdef __SSE2__
    for (; c < w && x0 + c + 16 <= mask.cols; c += 16) {
      const int m = _mm_movemask_epi8(_mm_loadu_si128(reinterpret_cast<const __m128i*>(row + c)));
      out[c >> 3] = static_cast<std::uint8_t>(m);
      out[(c >> 3) + 1] = static_cast<std::uint8_t>(m >> 8);
    }
#endif
    for (; c < w; ++c)
      if (row[c] & 0x80) out[c >> 3] |= static_cast<std::uint8_t>(1u << (c & 7));
  }
  cv::Mat bin;
  cv::threshold(mask(cv::Rect(x0, y0, w, h)), bin, 127, 1, cv::THRESH_BINARY);
  cv::integral(bin, f.integral, CV_32S);
  return f;
}

}  // namespace detail

// ---------------------------------------------------------------------------------------------
// Carving
// ---------------------------------------------------------------------------------------------
namespace {

Grid makeGrid(const HullOptions& options) {
  Grid g;
  g.origin = options.volume.min();
  g.voxel = options.voxel_m;
  const Eigen::Vector3d size = options.volume.sizes();
  for (int a = 0; a < 3; ++a)
    g.dims[a] = std::max(1, static_cast<int>(std::ceil(size[a] / g.voxel - 1e-9)));
  const int largest = g.dims.maxCoeff();
  while (((largest + (1 << g.top_level) - 1) >> g.top_level) > kTopCellsPerAxis) ++g.top_level;
  return g;
}

// Lattice of a parent's 8 children: 3 x 3 x 3 points, index (iz * 3 + iy) * 3 + ix.
struct ChildLattice {
  std::array<std::array<std::uint8_t, 8>, 8> corner;  // child -> its 8 lattice points
  std::array<std::uint32_t, 8> corner_mask;           // child -> bit set of those points
  ChildLattice() {
    for (int c = 0; c < 8; ++c) {
      corner_mask[c] = 0;
      for (int q = 0; q < 8; ++q) {
        const int ix = (c & 1) + (q & 1), iy = ((c >> 1) & 1) + ((q >> 1) & 1),
                  iz = (c >> 2) + (q >> 2);
        corner[c][q] = static_cast<std::uint8_t>((iz * 3 + iy) * 3 + ix);
        corner_mask[c] |= 1u << corner[c][q];
      }
    }
  }
};
const ChildLattice& childLattice() {
  static const ChildLattice lattice;
  return lattice;
}

struct LatticePoint {
  double x, y, u, v;
  bool valid, behind;
};

struct CarveContext {
  const std::vector<CameraModel>* cameras;
  const std::vector<FrameCam>* frames;
  Grid grid;
  int k = 0, min_views = 2;
  int set_words = 1;  // words per camera set (detail/hull_data.h)
};

// Footprint state of one child in one camera from its projected corners. Inlined by force: in
// latticeStates' PREVIZ_WIDE versions GCC no longer inlined it on its own.
[[gnu::always_inline]] inline CamState childState(const CameraModel& cam, const FrameCam& frame,
                                                  const LatticePoint* pts,
                                                  const std::array<std::uint8_t, 8>& corners) {
  double umin = kInf, umax = -kInf, vmin = kInf, vmax = -kInf;
  double xmin = kInf, xmax = -kInf, ymin = kInf, ymax = -kInf;
  bool any_invalid = false, all_behind = true;
  for (int q = 0; q < 8; ++q) {
    const LatticePoint& p = pts[corners[q]];
    if (!p.behind) all_behind = false;
    if (!p.valid) {
      any_invalid = true;
      continue;
    }
    umin = std::min(umin, p.u);
    umax = std::max(umax, p.u);
    vmin = std::min(vmin, p.v);
    vmax = std::max(vmax, p.v);
    xmin = std::min(xmin, p.x);
    xmax = std::max(xmax, p.x);
    ymin = std::min(ymin, p.y);
    ymax = std::max(ymax, p.y);
  }
  // Behind the camera as a whole (the cell is convex): unseen. Partly behind or past the
  // valid disc: undecided, left to the children and finally to the point test.
  if (any_invalid) return all_behind ? detail::kUnseen : detail::kMixed;
  const double dx = xmax - xmin, dy = ymax - ymin;
  const double pad = cam.pad_per_diam2 * (dx * dx + dy * dy) + detail::kPadEpsPx;
  return detail::rectState(frame, umin - pad, umax + pad, vmin - pad, vmax + pad);
}

// Largest second-order pad (px) for which the affine footprint is used; coarser cells project
// their 27 lattice corners instead.
constexpr double kAffineMaxPadPx = 0.5;

// Children states in one camera from the parent's affine image: at the parent's centre c the
// projection is pixel(c) + J h + O(|h|^2), and the second-order term is bounded by
// CameraModel::pad_per_h2. A child's footprint then lies in the box of its centre's affine image
// grown by the child's half extents |J| he plus that pad: one projection per parent and camera
// instead of up to 27. False when the parent is too large or too near the valid disc's edge.
// Inlined by force: splitParent's two instances made GCC call it, 2 % of the 8-camera carve.
[[gnu::always_inline]] inline bool affineStates(const CameraModel& cam, const FrameCam& frame,
                                                const double* centre, double he,
                                                const bool* alive, CamState* states) {
  double q[3];
  cam.toCamera(centre, q);
  const double hd = 2.0 * std::sqrt(3.0) * he;  // parent half-diagonal
  const double z_min = q[2] - hd;
  if (!(z_min > detail::kZNear)) return false;
  const double iz = 1.0 / q[2];
  const double x = q[0] * iz, y = q[1] * iz;
  const double r = std::sqrt(x * x + y * y);
  if (r + hd * (1.0 + r) / z_min > cam.r_valid) return false;
  const double pad = cam.pad_per_h2 * hd * hd / (z_min * z_min) + detail::kPadEpsPx;
  if (pad > kAffineMaxPadPx) return false;
  double Jn[4];
  cam.pixelJacobian(x, y, Jn);
  // d pixel / d world = Jn * D pi * R with D pi = [1 0 -x; 0 1 -y] / z.
  const double A[6] = {Jn[0] * iz, Jn[1] * iz, -(Jn[0] * x + Jn[1] * y) * iz,
                       Jn[2] * iz, Jn[3] * iz, -(Jn[2] * x + Jn[3] * y) * iz};
  double J[6];
  for (int row = 0; row < 2; ++row)
    for (int col = 0; col < 3; ++col)
      J[row * 3 + col] = A[row * 3] * cam.R[col] + A[row * 3 + 1] * cam.R[3 + col] +
                         A[row * 3 + 2] * cam.R[6 + col];
  double u, v;
  cam.toPixel(x, y, u, v);
  const double wu = he * (std::abs(J[0]) + std::abs(J[1]) + std::abs(J[2])) + pad;
  const double wv = he * (std::abs(J[3]) + std::abs(J[4]) + std::abs(J[5])) + pad;
  const double ju[3] = {he * J[0], he * J[1], he * J[2]};
  const double jv[3] = {he * J[3], he * J[4], he * J[5]};
  for (int c = 0; c < 8; ++c) {
    if (!alive[c]) continue;
    const double sx = (c & 1) ? 1.0 : -1.0, sy = (c & 2) ? 1.0 : -1.0, sz = (c & 4) ? 1.0 : -1.0;
    const double uc = u + sx * ju[0] + sy * ju[1] + sz * ju[2];
    const double vc = v + sx * jv[0] + sy * jv[1] + sz * jv[2];
    states[c] = detail::rectState(frame, uc - wu, uc + wu, vc - wv, vc + wv);
  }
  return true;
}

// Children states in one camera from their projected corners (the 3x3x3 lattice, each point
// projected once) and the distortion pad of each child's footprint.
PREVIZ_WIDE
void latticeStates(const CameraModel& cam, const FrameCam& frame, const double* corner0,
                   double edge, const bool* alive, CamState* states) {
  const ChildLattice& lattice = childLattice();
  std::uint32_t needed = 0;
  for (int c = 0; c < 8; ++c)
    if (alive[c]) needed |= lattice.corner_mask[c];
  // Corner (ix, iy, iz) in camera coordinates: q0 + ix a + iy b + iz c.
  double q0[3];
  cam.toCamera(corner0, q0);
  const double ax[3] = {cam.R[0] * edge, cam.R[3] * edge, cam.R[6] * edge};
  const double ay[3] = {cam.R[1] * edge, cam.R[4] * edge, cam.R[7] * edge};
  const double az[3] = {cam.R[2] * edge, cam.R[5] * edge, cam.R[8] * edge};
  LatticePoint pts[27];
  while (needed) {
    const int li = __builtin_ctz(needed);
    needed &= needed - 1;
    const int ix = li % 3, iy = (li / 3) % 3, iz = li / 9;
    double q[3];
    for (int a = 0; a < 3; ++a) q[a] = q0[a] + ix * ax[a] + iy * ay[a] + iz * az[a];
    LatticePoint& p = pts[li];
    p.behind = !(q[2] > detail::kZNear);
    p.valid = false;
    if (p.behind) continue;
    const double iqz = 1.0 / q[2];
    p.x = q[0] * iqz;
    p.y = q[1] * iqz;
    if (p.x * p.x + p.y * p.y > cam.r2_valid) continue;
    p.valid = true;
    cam.toPixel(p.x, p.y, p.u, p.v);
  }
  for (int c = 0; c < 8; ++c)
    if (alive[c]) states[c] = childState(cam, frame, pts, lattice.corner[c]);
}

// Splits one mixed parent (its mixed set: parent_set) into its children at 'level' and sorts
// them into dropped / inside / mixed (see the file comment). out.child_sets holds 8 sets.
// kWords: words per camera set, 0 = ctx.set_words (see carveLevels).
template <int kWords>
PREVIZ_WIDE
void splitParent(const Cell& parent, const std::uint64_t* parent_set, int level,
                 const CarveContext& ctx, BlockOut& out) {
  const Grid& g = ctx.grid;
  const int span = 1 << level;  // child edge in finest voxels
  Cell child[8];
  bool alive[8];
  bool boundary[8];
  int n_alive = 0;
  for (int c = 0; c < 8; ++c) {
    const int idx[3] = {2 * parent.x + (c & 1), 2 * parent.y + ((c >> 1) & 1),
                        2 * parent.z + (c >> 2)};
    alive[c] = true;
    boundary[c] = false;
    for (int a = 0; a < 3; ++a) {
      if (static_cast<long long>(idx[a]) * span >= g.dims[a]) alive[c] = false;
      // Cells on the volume's boundary are never kept whole: the mesh closes the hull there.
      if (idx[a] == 0 || static_cast<long long>(idx[a] + 1) * span >= g.dims[a])
        boundary[c] = true;
    }
    child[c].x = static_cast<std::uint16_t>(idx[0]);
    child[c].y = static_cast<std::uint16_t>(idx[1]);
    child[c].z = static_cast<std::uint16_t>(idx[2]);
    child[c].level = static_cast<std::uint8_t>(level);
    child[c].n_out = parent.n_out;
    child[c].n_in = parent.n_in;
    n_alive += alive[c];
  }
  const int words = kWords > 0 ? kWords : ctx.set_words;
  std::uint64_t* child_set = out.child_sets.data();  // child c's set at c * words
  std::fill(child_set, child_set + 8 * words, std::uint64_t{0});
  out.tested += n_alive;

  const double edge = g.voxel * span;
  const double corner0[3] = {g.origin.x() + edge * 2 * parent.x,
                             g.origin.y() + edge * 2 * parent.y,
                             g.origin.z() + edge * 2 * parent.z};
  const double centre[3] = {corner0[0] + edge, corner0[1] + edge, corner0[2] + edge};
  CamState states[8];
  for (int w = 0; w < words && n_alive > 0; ++w) {
    for (std::uint64_t remaining = parent_set[w]; remaining && n_alive > 0;
         remaining &= remaining - 1) {
      const int bit_index = __builtin_ctzll(remaining);
      const int cam_index = w * detail::kCamerasPerWord + bit_index;
      const CameraModel& cam = (*ctx.cameras)[cam_index];
      const FrameCam& frame = (*ctx.frames)[cam_index];
      if (!affineStates(cam, frame, centre, 0.5 * edge, alive, states))
        latticeStates(cam, frame, corner0, edge, alive, states);
      const std::uint64_t bit = std::uint64_t{1} << bit_index;
      for (int c = 0; c < 8; ++c) {
        if (!alive[c]) continue;
        switch (states[c]) {
          case detail::kOut:
            if (++child[c].n_out > ctx.k) {
              alive[c] = false;
              --n_alive;
            }
            break;
          case detail::kIn:
            ++child[c].n_in;
            break;
          case detail::kMixed:
            child_set[c * words + w] |= bit;
            break;
          case detail::kUnseen:
            break;
        }
      }
    }
  }
  for (int c = 0; c < 8; ++c) {
    if (!alive[c]) continue;
    const Cell& ch = child[c];
    const std::uint64_t* set = child_set + c * words;
    const int n_mixed = detail::cameraSetCount(set, words);
    if (ch.n_in + ch.n_out + n_mixed < ctx.min_views) continue;  // seen by too few
    if (ch.n_out + n_mixed <= ctx.k && ch.n_in + ch.n_out >= ctx.min_views && !boundary[c]) {
      out.inside.push_back(ch);
    } else {
      out.mixed.push_back(ch);
      for (int w = 0; w < words; ++w) out.mixed_sets.push_back(set[w]);
    }
  }
}

HullCell toHullCell(const Cell& c) {
  HullCell h;
  h.index = Eigen::Vector3i(c.x, c.y, c.z);
  h.level = c.level;
  return h;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Carver state (carving/detail/carver_impl.h)
// ---------------------------------------------------------------------------------------------
std::shared_ptr<const RayTable> Carver::Impl::rayTable(const Camera& camera, int threads) const {
  std::lock_guard<std::mutex> lock(rays_mutex);
  for (const auto& table : rays)
    if (detail::sameLens(table->camera, camera)) return table;
  auto table = std::make_shared<RayTable>();
  table->camera = camera;
  table->xy.assign(2 * static_cast<size_t>(camera.width) * camera.height,
                   std::numeric_limits<float>::quiet_NaN());
  const InverseDistortion inverse(camera.dist);
  const bool distorted = !camera.dist.isZero();
#pragma omp parallel for schedule(dynamic, 8) num_threads(threads)
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      const Eigen::Vector2d xd = camera.pixelToNormalized(Eigen::Vector2d(u, v));
      Eigen::Vector2d x = xd;
      if (distorted) {
        const InverseResult r = inverse.solve(xd);
        if (!r.ok()) continue;
        x = r.point;
      }
      const size_t i = 2 * (static_cast<size_t>(v) * camera.width + u);
      table->xy[i] = static_cast<float>(x.x());
      table->xy[i + 1] = static_cast<float>(x.y());
    }
  }
  RigCamera at_origin;
  at_origin.camera = camera;
  table->model = detail::makeCameraModel(at_origin);
  rays.push_back(table);
  return table;
}

Carver::Carver(std::vector<RigCamera> cameras, const HullOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.validate();
  if (cameras.empty())
    throw Error("carve: no cameras to carve with", fieldContext("cameras"));
  auto models = std::make_shared<std::vector<CameraModel>>();
  for (const RigCamera& c : cameras) models->push_back(detail::makeCameraModel(c));
  impl_->cameras = std::move(cameras);
  impl_->models = std::move(models);
  impl_->options = options;
  impl_->grid = makeGrid(options);
}

Carver::~Carver() = default;

const std::vector<RigCamera>& Carver::cameras() const { return impl_->cameras; }
const HullOptions& Carver::options() const { return impl_->options; }

namespace {

// ---------------------------------------------------------------------------------------------
// Carving levels and the brick lookup
// ---------------------------------------------------------------------------------------------
constexpr int kBlock = 64;  // parents per work item: results are gathered in block order

// The surface cells' mixed sets go to surface_sets (ctx.set_words words each). Rigs of up to 64
// cameras (the live ones) run with kWords = 1, where the set loops compile away: with the word
// count read at run time the 8-camera carve took 4-7 % longer. Larger rigs run with kWords = 0.
template <int kWords>
void carveLevels(const CarveContext& ctx, const std::vector<std::uint64_t>& used_set,
                 int threads, std::vector<BlockOut>& blocks, std::vector<Cell>& inside,
                 std::vector<Cell>& surface, std::vector<std::uint64_t>& surface_sets,
                 std::vector<long long>& tested) {
  const Grid& g = ctx.grid;
  const int words = kWords > 0 ? kWords : ctx.set_words;
  // The top cells are the children of virtual parents one level up, undecided everywhere.
  const int pl = g.top_level + 1;
  Eigen::Vector3i pd;
  for (int a = 0; a < 3; ++a) pd[a] = (g.dims[a] + (1 << pl) - 1) >> pl;
  std::vector<Cell> parents, next;
  std::vector<std::uint64_t> parent_sets, next_sets;
  for (int z = 0; z < pd.z(); ++z)
    for (int y = 0; y < pd.y(); ++y)
      for (int x = 0; x < pd.x(); ++x) {
        Cell c;
        c.x = static_cast<std::uint16_t>(x);
        c.y = static_cast<std::uint16_t>(y);
        c.z = static_cast<std::uint16_t>(z);
        c.level = static_cast<std::uint8_t>(pl);
        parents.push_back(c);
        parent_sets.insert(parent_sets.end(), used_set.begin(), used_set.end());
      }
  for (int level = g.top_level; level >= 0 && !parents.empty(); --level) {
    const long long n = static_cast<long long>(parents.size());
    const int n_blocks = static_cast<int>((n + kBlock - 1) / kBlock);
    if (static_cast<int>(blocks.size()) < n_blocks) blocks.resize(n_blocks);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (int b = 0; b < n_blocks; ++b) {
      BlockOut& out = blocks[b];
      out.clear();
      out.child_sets.resize(8 * static_cast<size_t>(words));
      const long long end = std::min(n, static_cast<long long>(b + 1) * kBlock);
      for (long long i = static_cast<long long>(b) * kBlock; i < end; ++i)
        splitParent<kWords>(parents[i], parent_sets.data() + i * words, level, ctx, out);
    }
    next.clear();
    next_sets.clear();
    std::vector<Cell>& mixed_target = level == 0 ? surface : next;
    std::vector<std::uint64_t>& sets_target = level == 0 ? surface_sets : next_sets;
    for (int b = 0; b < n_blocks; ++b) {
      const BlockOut& out = blocks[b];
      tested[g.top_level - level] += out.tested;
      inside.insert(inside.end(), out.inside.begin(), out.inside.end());
      mixed_target.insert(mixed_target.end(), out.mixed.begin(), out.mixed.end());
      sets_target.insert(sets_target.end(), out.mixed_sets.begin(), out.mixed_sets.end());
    }
    parents.swap(next);
    parent_sets.swap(next_sets);
  }
}

// Fills h's brick lookup (detail/hull_data.h) from the kept cells and the surface cells' mixed
// sets.
PREVIZ_WIDE
void buildBricks(HullData& h, const std::vector<Cell>& inside, const std::vector<Cell>& surface,
                 const std::vector<std::uint64_t>& surface_sets, int threads) {
  if (inside.empty() && surface.empty()) return;
  Eigen::Vector3i lo = h.dims, hi = Eigen::Vector3i::Zero();
  auto extend = [&](const Cell& c) {
    const int s = 1 << c.level;
    const int idx[3] = {c.x, c.y, c.z};
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], idx[a] * s);
      hi[a] = std::max(hi[a], std::min((idx[a] + 1) * s, h.dims[a]));
    }
  };
  for (const Cell& c : inside) extend(c);
  for (const Cell& c : surface) extend(c);
  for (int a = 0; a < 3; ++a) {
    h.brick_min[a] = lo[a] >> detail::kBrickShift;
    h.brick_dims[a] = ((hi[a] - 1) >> detail::kBrickShift) - h.brick_min[a] + 1;
  }
  const Eigen::Vector3i bd = h.brick_dims;
  h.brick_index.assign(static_cast<size_t>(bd.x()) * bd.y() * bd.z(), detail::kBrickEmpty);
  auto brickOf = [&](int vx, int vy, int vz) {
    const int bx = (vx >> detail::kBrickShift) - h.brick_min.x();
    const int by = (vy >> detail::kBrickShift) - h.brick_min.y();
    const int bz = (vz >> detail::kBrickShift) - h.brick_min.z();
    return (static_cast<size_t>(bz) * bd.y() + by) * bd.x() + bx;
  };
  auto voxelBits = [](const Cell& c) {
    const int s = 1 << c.level;
    std::uint64_t bits = 0;
    for (int dz = 0; dz < s; ++dz)
      for (int dy = 0; dy < s; ++dy)
        for (int dx = 0; dx < s; ++dx) {
          const int vx = c.x * s + dx, vy = c.y * s + dy, vz = c.z * s + dz;
          bits |= std::uint64_t{1} << (((vz & 3) << 4) | ((vy & 3) << 2) | (vx & 3));
        }
    return bits;
  };
  // Inside cells of a brick's size or more fill whole bricks (serial: there are few).
  std::vector<const Cell*> small_inside;
  for (const Cell& c : inside) {
    if (c.level < detail::kBrickShift) {
      small_inside.push_back(&c);
      continue;
    }
    const int s = 1 << c.level;
    const int x1 = std::min((c.x + 1) * s, h.dims.x()), y1 = std::min((c.y + 1) * s, h.dims.y()),
              z1 = std::min((c.z + 1) * s, h.dims.z());
    for (int z = c.z * s; z < z1; z += detail::kBrickEdge)
      for (int y = c.y * s; y < y1; y += detail::kBrickEdge)
        for (int x = c.x * s; x < x1; x += detail::kBrickEdge)
          h.brick_index[brickOf(x, y, z)] = detail::kBrickFull;
  }
  // Smaller cells: mark their bricks, number the marked bricks in grid order (deterministic),
  // then OR the cells' voxel bits into them.
  constexpr std::int32_t kMarked = -3;
  const long long n_small = static_cast<long long>(small_inside.size());
  const long long n_surface = static_cast<long long>(surface.size());
#pragma omp parallel num_threads(threads)
  {
#pragma omp for schedule(static) nowait
    for (long long i = 0; i < n_small; ++i) {
      const Cell& c = *small_inside[i];
      const int s = 1 << c.level;
      __atomic_store_n(&h.brick_index[brickOf(c.x * s, c.y * s, c.z * s)], kMarked,
                       __ATOMIC_RELAXED);
    }
#pragma omp for schedule(static)
    for (long long i = 0; i < n_surface; ++i) {
      const Cell& c = surface[i];
      __atomic_store_n(&h.brick_index[brickOf(c.x, c.y, c.z)], kMarked, __ATOMIC_RELAXED);
    }
  }
  std::int32_t n_bricks = 0;
  for (std::int32_t& b : h.brick_index)
    if (b == kMarked) b = n_bricks++;
  h.bricks.assign(n_bricks, detail::Brick{});
#pragma omp parallel num_threads(threads)
  {
#pragma omp for schedule(static) nowait
    for (long long i = 0; i < n_small; ++i) {
      const Cell& c = *small_inside[i];
      const int s = 1 << c.level;
      detail::Brick& b = h.bricks[h.brick_index[brickOf(c.x * s, c.y * s, c.z * s)]];
      __atomic_fetch_or(&b.inside, voxelBits(c), __ATOMIC_RELAXED);
    }
#pragma omp for schedule(static)
    for (long long i = 0; i < n_surface; ++i) {
      const Cell& c = surface[i];
      detail::Brick& b = h.bricks[h.brick_index[brickOf(c.x, c.y, c.z)]];
      __atomic_fetch_or(&b.surface, voxelBits(c), __ATOMIC_RELAXED);
    }
  }
  std::uint32_t total = 0;
  for (detail::Brick& b : h.bricks) {
    b.offset = total;
    total += static_cast<std::uint32_t>(__builtin_popcountll(b.surface));
  }
  const int words = h.set_words;
  h.surface_info.resize(total);
  h.surface_mixed.resize(static_cast<size_t>(total) * words);
  h.surface_voxel.resize(total);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (long long i = 0; i < n_surface; ++i) {
    const Cell& c = surface[i];
    const detail::Brick& b = h.bricks[h.brick_index[brickOf(c.x, c.y, c.z)]];
    const std::uint64_t m = std::uint64_t{1} << (((c.z & 3) << 4) | ((c.y & 3) << 2) | (c.x & 3));
    const std::uint32_t pos = b.offset + __builtin_popcountll(b.surface & (m - 1));
    // Word by word: std::copy_n of a run-time count is a memmove call per voxel.
    for (int w = 0; w < words; ++w)
      h.surface_mixed[static_cast<size_t>(pos) * words + w] = surface_sets[i * words + w];
    h.surface_info[pos].n_out = c.n_out;
    h.surface_info[pos].n_in = c.n_in;
    h.surface_voxel[pos] = Eigen::Matrix<std::int32_t, 3, 1>(c.x, c.y, c.z);
  }
}

}  // namespace

VisualHull Carver::carve(const Silhouettes& silhouettes) {
  const Stopwatch start;
  Impl& im = *impl_;
  const int n = static_cast<int>(im.cameras.size());
  if (static_cast<int>(silhouettes.masks.size()) != n)
    throw Error("carve: got " + std::to_string(silhouettes.masks.size()) + " silhouettes for " +
                    std::to_string(n) + " cameras",
                fieldContext("masks"));
  if (!silhouettes.dropped.empty() && static_cast<int>(silhouettes.dropped.size()) != n)
    throw Error("carve: got " + std::to_string(silhouettes.dropped.size()) +
                    " drop reasons for " + std::to_string(n) + " cameras",
                fieldContext("dropped"));
  const int threads = resolveThreads(im.options.threads);

  auto data = std::make_shared<HullData>();
  data->origin = im.grid.origin;
  data->voxel = im.grid.voxel;
  data->dims = im.grid.dims;
  data->k = im.options.k;
  data->min_views = im.options.min_views;
  data->cameras = im.models;
  data->frames.resize(n);
  data->set_words = detail::cameraSetWords(n);
  data->used_set.assign(data->set_words, 0);

  VisualHull hull;
  hull.origin = im.grid.origin;
  hull.voxel_m = im.grid.voxel;
  hull.levels = im.grid.top_level + 1;
  hull.stats.cells_tested.assign(hull.levels, 0);
  for (int c = 0; c < n; ++c) {
    const std::string& name = im.cameras[c].camera.name;
    const cv::Mat& mask = silhouettes.masks[c];
    std::string reason = silhouettes.dropped.empty() ? std::string() : silhouettes.dropped[c];
    if (reason.empty() && mask.empty()) reason = "no silhouette (empty mask)";
    if (!reason.empty()) {
      hull.stats.cameras_dropped.push_back(name);
      hull.stats.drop_reasons.push_back(reason);
      continue;
    }
    if (mask.type() != CV_8UC1)
      throw Error("carve: silhouette must be 8-bit single-channel (got OpenCV type " +
                      std::to_string(mask.type()) + ")",
                  ErrorContext{"", name, std::nullopt, "masks"});
    if (mask.cols != im.cameras[c].camera.width || mask.rows != im.cameras[c].camera.height)
      throw Error("carve: silhouette is " + std::to_string(mask.cols) + "x" +
                      std::to_string(mask.rows) + " but the camera is " +
                      std::to_string(im.cameras[c].camera.width) + "x" +
                      std::to_string(im.cameras[c].camera.height),
                  ErrorContext{"", name, std::nullopt, "masks"});
    data->used.push_back(c);
    data->used_set[c / detail::kCamerasPerWord] |= std::uint64_t{1} << (c % detail::kCamerasPerWord);
    hull.stats.cameras_used.push_back(name);
  }
  const int n_used = static_cast<int>(data->used.size());
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int i = 0; i < n_used; ++i)
    data->frames[data->used[i]] = detail::makeFrameCam(silhouettes.masks[data->used[i]]);

  std::vector<Cell> inside, surface;
  std::vector<std::uint64_t> surface_sets;
  if (n_used >= im.options.min_views) {
    CarveContext ctx{im.models.get(), &data->frames, im.grid,
                     im.options.k, im.options.min_views, data->set_words};
    (data->set_words == 1 ? carveLevels<1> : carveLevels<0>)(
        ctx, data->used_set, threads, im.blocks, inside, surface, surface_sets,
        hull.stats.cells_tested);
  }
  buildBricks(*data, inside, surface, surface_sets, threads);

  hull.inside.resize(inside.size());
  hull.surface.resize(surface.size());
  std::transform(inside.begin(), inside.end(), hull.inside.begin(), toHullCell);
  std::transform(surface.begin(), surface.end(), hull.surface.begin(), toHullCell);
  hull.stats.inside_cells = static_cast<long long>(inside.size());
  hull.stats.surface_cells = static_cast<long long>(surface.size());
  hull.data = data;
  im.last = data;
  hull.stats.ms = start.ms();
  return hull;
}

bool Carver::inside(const Eigen::Vector3d& p_world) const {
  return impl_->last && impl_->last->inside(p_world.data());
}

bool Carver::inside(const VisualHull& hull, const Eigen::Vector3d& p_world) const {
  return hull.data && hull.data->inside(p_world.data());
}

}  // namespace previz::carving
