#pragma once
// What a carved frame keeps for depth(), mesh() and the point test: the frame's silhouettes,
// the k-of-n rule, and the kept cells in a two-level lookup (a dense grid of 4x4x4-voxel bricks
// over the hull's bounding box; each brick empty, wholly inside, or a pair of 64-bit masks of
// inside / surface voxels). Surface voxels carry what carving learnt about them: the cameras
// that see them wholly outside / inside, and the cameras still undecided (mixed) — the exact
// point test inside a surface voxel only needs to look at those. Internal to carving/hull.cpp.
//
// Camera sets (the mixed cameras of a cell or surface voxel, the used cameras of a frame) are
// bit sets of set_words 64-bit words, camera c at bit c % 64 of word c / 64, stored out of line
// in flat arrays (set i at words i * set_words ...): one word up to 64 cameras, as many as the
// rig needs beyond. Walking a set visits the cameras in index order, so the k-of-n rule's early
// exits, and with them the results, do not depend on the word count.
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "carving/detail/hull_camera.h"

namespace previz::carving::detail {

constexpr int kBrickShift = 2;  // bricks of 4^3 finest voxels: one 64-bit mask each
constexpr int kBrickEdge = 1 << kBrickShift;

constexpr int kCamerasPerWord = 64;

// Words of a camera set over n cameras.
inline int cameraSetWords(int n_cameras) {
  return (n_cameras + kCamerasPerWord - 1) / kCamerasPerWord;
}
inline int cameraSetCount(const std::uint64_t* set, int words) {
  int n = 0;
  for (int w = 0; w < words; ++w) n += __builtin_popcountll(set[w]);
  return n;
}

struct SurfaceInfo {
  std::int32_t n_out = 0;  // cameras that see the whole voxel outside the silhouette
  std::int32_t n_in = 0;   // cameras that see the whole voxel inside
};

struct Brick {
  std::uint64_t inside = 0;   // bit (z*16 + y*4 + x): voxel wholly inside
  std::uint64_t surface = 0;  // voxel is a surface voxel
  std::uint32_t offset = 0;   // index of its first surface voxel in HullData::surface_*
};

constexpr std::int32_t kBrickEmpty = -1;
constexpr std::int32_t kBrickFull = -2;

enum VoxelKind : std::uint8_t { kVoxelEmpty = 0, kVoxelInside = 1, kVoxelSurface = 2 };

struct HullData {
  // Finest grid: voxel (i, j, k) spans origin + voxel * [i, i+1] x ...; dims voxels per axis.
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double voxel = 0;
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();
  int k = 0, min_views = 2;

  std::shared_ptr<const std::vector<CameraModel>> cameras;
  std::vector<FrameCam> frames;  // one per camera; !used = dropped this frame
  std::vector<int> used;         // indices of the used cameras
  int set_words = 1;             // words per camera set (cameraSetWords of the rig's cameras)
  std::vector<std::uint64_t> used_set;  // the used cameras as a set

  // Brick grid over the kept cells' bounding box (brick units).
  Eigen::Vector3i brick_min = Eigen::Vector3i::Zero(), brick_dims = Eigen::Vector3i::Zero();
  std::vector<std::int32_t> brick_index;  // kBrickEmpty, kBrickFull or index into bricks
  std::vector<Brick> bricks;
  // Surface voxels in brick order (brick by brick, bit order within a brick), with the cameras
  // to test at a point of each (its mixed set, at surface_mixed.data() + index * set_words).
  std::vector<SurfaceInfo> surface_info;
  std::vector<std::uint64_t> surface_mixed;
  std::vector<Eigen::Matrix<std::int32_t, 3, 1>> surface_voxel;

  bool hasCells() const { return !brick_index.empty(); }
  const std::uint64_t* surfaceMixed(std::int64_t surface_index) const {
    return surface_mixed.data() + surface_index * set_words;
  }

  // Kind of finest voxel v; for surface voxels also its index into surface_*.
  inline VoxelKind voxelKind(int x, int y, int z, std::int64_t* surface_index = nullptr) const {
    const int bx = (x >> kBrickShift) - brick_min.x(), by = (y >> kBrickShift) - brick_min.y(),
              bz = (z >> kBrickShift) - brick_min.z();
    if (x < 0 || y < 0 || z < 0 || bx < 0 || by < 0 || bz < 0 || bx >= brick_dims.x() ||
        by >= brick_dims.y() || bz >= brick_dims.z())
      return kVoxelEmpty;
    const std::int32_t b = brick_index[(static_cast<std::int64_t>(bz) * brick_dims.y() + by) *
                                           brick_dims.x() + bx];
    if (b == kBrickEmpty) return kVoxelEmpty;
    if (b == kBrickFull) return kVoxelInside;
    const Brick& brick = bricks[b];
    const int bit = ((z & 3) << 4) | ((y & 3) << 2) | (x & 3);
    const std::uint64_t m = std::uint64_t{1} << bit;
    if (brick.inside & m) return kVoxelInside;
    if (!(brick.surface & m)) return kVoxelEmpty;
    if (surface_index)
      *surface_index = brick.offset + __builtin_popcountll(brick.surface & (m - 1));
    return kVoxelSurface;
  }

  // The k-of-n rule at a point, testing only the cameras in 'mixed' and starting from counts
  // already known for the region the point lies in.
  inline bool insideGiven(const double* p, const std::uint64_t* mixed, int n_out,
                          int n_in) const {
    int views = n_out + n_in;
    if (n_out > k) return false;
    for (int w = 0; w < set_words; ++w) {
      for (std::uint64_t bits = mixed[w]; bits; bits &= bits - 1) {
        const int c = w * kCamerasPerWord + __builtin_ctzll(bits);
        const CamState s = pointState((*cameras)[c], frames[c], p);
        if (s == kOut) {
          if (++n_out > k) return false;
          ++views;
        } else if (s == kIn) {
          ++views;
        }
      }
    }
    return views >= min_views;
  }

  // Exact point test (all used cameras); false outside the carved volume.
  inline bool inside(const double* p) const {
    for (int a = 0; a < 3; ++a) {
      const double g = (p[a] - origin[a]) / voxel;
      if (!(g >= 0.0) || g > dims[a]) return false;
    }
    return insideGiven(p, used_set.data(), 0, 0);
  }
};

}  // namespace previz::carving::detail
