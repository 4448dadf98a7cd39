#pragma once
// What the three parts of the Carver share (carving/hull.cpp: carving and the point test,
// hull_depth.cpp: depth for any camera, hull_mesh.cpp: the surface mesh): the Carver's state, the
// cells carving passes between levels, the per-lens ray tables of depth(), and the sampling
// constants along a ray. Internal to carving/.
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Core>

#include "carving/detail/hull_camera.h"
#include "carving/detail/hull_data.h"
#include "carving/hull.h"

namespace previz::carving::detail {

// Along a ray inside a surface voxel: samples every voxel / kSamplesPerVoxel (or every
// HullOptions::depth_step_m when set), then bisection between the last outside and the first
// inside sample (the surface to 1/32 of the sampling step: 0.08 mm at 5 mm cells). Mesh edges
// use the same bisection.
inline constexpr int kSamplesPerVoxel = 2;
inline constexpr int kRefineIterations = 5;

// The finest grid over the volume and the number of levels above it.
struct Grid {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double voxel = 0;
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();
  int top_level = 0;
};

// A cell during carving: index at its level and the cameras known to see it wholly outside /
// inside (32-bit: rigs may hold hundreds of cameras; the cell stays 16 bytes). The cameras still
// undecided are its mixed set, kept beside it (detail/hull_data.h).
struct Cell {
  std::uint16_t x = 0, y = 0, z = 0;
  std::uint8_t level = 0;
  std::int32_t n_out = 0, n_in = 0;
};

// One work item's output: mixed cells with their sets (mixed_sets, set_words words each) and
// inside cells (which need none). child_sets is the scratch of one parent's 8 children, sized
// for the rig on first use: carving allocates nothing when warm.
struct BlockOut {
  std::vector<Cell> mixed, inside;
  std::vector<std::uint64_t> mixed_sets, child_sets;
  long long tested = 0;
  void clear() {
    mixed.clear();
    inside.clear();
    mixed_sets.clear();
    tested = 0;
  }
};

// What depth() needs of one lens, built on its first use: per-pixel rays (ideal normalized
// (x, y), NaN where not invertible) and the projection model (its pose set per call).
struct RayTable {
  Camera camera;
  std::vector<float> xy;
  CameraModel model;
};

inline bool sameLens(const Camera& a, const Camera& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy && a.skew == b.skew && a.dist == b.dist;
}

}  // namespace previz::carving::detail

namespace previz::carving {

struct Carver::Impl {
  std::vector<RigCamera> cameras;
  std::shared_ptr<const std::vector<detail::CameraModel>> models;
  HullOptions options;
  detail::Grid grid;
  std::shared_ptr<const detail::HullData> last;
  std::vector<detail::BlockOut> blocks;  // reused between frames: carving allocates nothing when warm

  mutable std::mutex rays_mutex;
  mutable std::vector<std::shared_ptr<const detail::RayTable>> rays;
  std::shared_ptr<const detail::RayTable> rayTable(const Camera& camera, int threads) const;
};

}  // namespace previz::carving
