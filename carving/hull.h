#pragma once
// Visual hull of the actor from the witness silhouettes: coarse-to-fine carving of a sparse cell
// hierarchy, k-of-n tolerance, per-pixel depth for any rig camera, and the hull surface as a
// mesh. One Carver per rig (it precomputes per-camera lookups once); carve() per frame.
// Cameras keep their true distortion: cell corners are projected through the lens (with a
// bound on the curvature of the footprint), never the silhouettes undistorted
// (carving/detail/hull_camera.h says why). The "exact" hull is the one of the pixel masks: a
// point is inside a silhouette when the pixel its projection falls in (OpenCV centre
// convention) is > 127. Conventions: docs/conventions.md.
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "core/mesh.h"
#include "core/rig.h"

namespace previz::carving {

namespace detail {
struct HullData;  // silhouettes of the frame + cell lookup (carving/detail/hull_data.h)
}

struct HullOptions {
  // Stage volume carved (world, metres).
  Eigen::AlignedBox3d volume{Eigen::Vector3d(-2.0, -2.0, 0.0), Eigen::Vector3d(2.0, 2.0, 2.5)};
  double voxel_m = 0.005;   // finest cell edge
  // Depth (Carver::depth): the step a ray samples the silhouettes at inside a surface cell before
  // it bisects to the crossing; a hull sliver thinner than the step can fall between two samples.
  // 0 = half the cell (voxel_m / 2).
  double depth_step_m = 0;
  // A cell survives if it lies outside the silhouette in at most k of the cameras that see it.
  // Cameras that do not see a cell (outside their image) never carve it.
  int k = 0;
  // A cell must be seen by at least this many cameras to survive (guards the volume's edge).
  int min_views = 2;
  int threads = 0;          // OpenMP threads (0 = default)
  void validate() const;    // throws Error naming the field
};

// One camera's input for one frame: silhouette (CV_8UC1, > 127 = inside, the camera's full
// image size). Empty = the camera is dropped for this frame (missing or bad frame).
// Dropped cameras are reported in HullStats::cameras_dropped with their reason.
struct Silhouettes {
  std::vector<cv::Mat> masks;          // order of the rig's cameras used by the Carver
  // Optional (empty, or one per camera): a non-empty reason drops the camera even when its
  // mask is given (a frame the caller flagged bad); "" = used when its mask is not empty.
  std::vector<std::string> dropped;
};

// A cell of the hierarchy: edge voxel_m * 2^level, min corner origin + index * edge. Cells that
// touch the volume's boundary are never "inside" (they end up as surface cells), so the mesh
// closes the hull there (e.g. the feet on the floor at z = 0).
struct HullCell {
  Eigen::Vector3i index;
  int level = 0;
};

struct HullStats {
  std::vector<long long> cells_tested;  // per level, coarsest first
  long long surface_cells = 0;          // finest-level cells the surface crosses
  long long inside_cells = 0;           // cells wholly inside (any level)
  double ms = 0;                        // wall time of carve()
  std::vector<std::string> cameras_used, cameras_dropped;
  std::vector<std::string> drop_reasons;  // same order as cameras_dropped
};

struct VisualHull {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();   // = options.volume.min()
  double voxel_m = 0;
  int levels = 0;                    // level 0 = finest
  std::vector<HullCell> inside;      // wholly inside, any level
  std::vector<HullCell> surface;     // level 0 cells neither wholly inside nor wholly outside
  HullStats stats;
  // What depth(), mesh() and inside(hull, p) need: this frame's silhouettes (shared, not
  // copied) and the cells in a lookup structure. A hull stays valid after later carve() calls.
  std::shared_ptr<const detail::HullData> data;
  bool empty() const { return inside.empty() && surface.empty(); }
};

class Carver {
 public:
  // cameras: the witness cameras carving uses (any subset of a rig, each with its distortion;
  // any number of them).
  Carver(std::vector<RigCamera> cameras, const HullOptions& options = {});
  ~Carver();
  Carver(const Carver&) = delete;
  Carver& operator=(const Carver&) = delete;

  const std::vector<RigCamera>& cameras() const;
  const HullOptions& options() const;

  // Carves one frame. Throws Error naming the camera when a mask has the wrong size/type;
  // a dropped camera is reported in stats.cameras_dropped, never fatal (fewer than 2 cameras
  // left: empty hull, reported).
  VisualHull carve(const Silhouettes& silhouettes);

  // Exact point test against the silhouettes of the last carve() (k-of-n rule as above);
  // false outside the volume and before any carve().
  bool inside(const Eigen::Vector3d& p_world) const;
  // The same against the silhouettes of a given hull.
  bool inside(const VisualHull& hull, const Eigen::Vector3d& p_world) const;

  // Depth for a camera (usually the main one, any pose and lens): for every pixel inside
  // 'silhouette' (CV_8UC1 > 127, or empty = every pixel), the metric depth (z along the camera
  // axis) of the first hull surface along the pixel's ray through the true lens: the ray walks
  // the kept cells, samples the exact point test in surface cells every half cell and finds the
  // crossing below that (pixel-edge crossing in the witness images, or bisection): the exact
  // visual hull of the masks to well under a millimetre. CV_32FC1, +inf where the ray misses.
  // The first call per lens builds its per-pixel ray table (~0.2 s at 1920x1080), then reused.
  cv::Mat depth(const VisualHull& hull, const RigCamera& camera, const cv::Mat& silhouette) const;
  // The same into 'out', reusing its buffer when it has the camera's size and type (the live loop
  // keeps one: no 8 MB allocation and its page faults per 1920x1080 frame). Images sharing that
  // buffer see it overwritten.
  void depth(const VisualHull& hull, const RigCamera& camera, const cv::Mat& silhouette, cv::Mat& out) const;

  // Surface mesh of the hull: surface nets over the surface cells (one vertex per cell the
  // surface crosses, at the mean of its edges' crossings, each found by bisection with the
  // exact point test; one quad per crossed lattice edge, split along its shorter diagonal),
  // Taubin-smoothed vertices, area-weighted outward normals. Closed where the cell field is
  // (the volume's boundary counts as outside); ambiguous cells may give non-manifold edges.
  TriangleMesh mesh(const VisualHull& hull) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::carving
