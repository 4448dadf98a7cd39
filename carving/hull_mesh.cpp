// The hull's surface mesh: surface nets over the surface voxels (carving/hull.h, Carver::mesh).
#include "carving/hull.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "carving/detail/carver_impl.h"
#include "carving/detail/hull_camera.h"
#include "carving/detail/hull_data.h"
#include "core/error.h"
#include "core/threads.h"

namespace previz::carving {

using detail::HullData;
using detail::kRefineIterations;

// ---------------------------------------------------------------------------------------------
// Mesh: surface nets over the surface voxels
// ---------------------------------------------------------------------------------------------
namespace {

constexpr int kSmoothPairs = 3;  // Taubin (1995) lambda/mu pairs: smooths without shrinking
constexpr double kTaubinLambda = 0.5, kTaubinMu = -0.53;

// Corner c = dx + 2 dy + 4 dz of a voxel; lattice of a brick: 5^3 points.
int latticeIndex(int lx, int ly, int lz) { return (lz * 5 + ly) * 5 + lx; }

struct MeshBuilder {
  const HullData& h;
  int threads;
  std::vector<std::int8_t> sign;     // per brick, 125 lattice signs (-1 unknown, 0 out, 1 in)
  std::vector<std::int32_t> brick_of;  // surface voxel -> brick
  std::vector<std::uint8_t> code;    // surface voxel -> corner inside bits
  std::vector<Eigen::Vector3d> vertex;

  Eigen::Vector3d latticePoint(int x, int y, int z) const {
    return h.origin + h.voxel * Eigen::Vector3d(x, y, z);
  }
  bool cornerInside(std::int64_t s, int c) const {
    return (code[s] >> c) & 1;
  }

  // Lattice signs from the exact test with every used camera (the same answer for a point
  // shared by two bricks); the volume's boundary is outside, which closes the hull there.
  void computeSigns() {
    const int n_bricks = static_cast<int>(h.bricks.size());
    sign.assign(static_cast<size_t>(n_bricks) * 125, -1);
    brick_of.assign(h.surface_info.size(), -1);
    code.assign(h.surface_info.size(), 0);
    const std::uint64_t* all = h.used_set.data();
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads)
    for (int b = 0; b < n_bricks; ++b) {
      const detail::Brick& brick = h.bricks[b];
      const int count = __builtin_popcountll(brick.surface);
      std::int8_t* bs = sign.data() + static_cast<size_t>(b) * 125;
      for (int k = 0; k < count; ++k) {
        const std::int64_t s = brick.offset + k;
        brick_of[s] = b;
        const auto& v = h.surface_voxel[s];
        std::uint8_t bits = 0;
        for (int c = 0; c < 8; ++c) {
          const int gx = v.x() + (c & 1), gy = v.y() + ((c >> 1) & 1), gz = v.z() + (c >> 2);
          const int li = latticeIndex(gx - (v.x() & ~3), gy - (v.y() & ~3), gz - (v.z() & ~3));
          if (bs[li] < 0) {
            const bool boundary = gx <= 0 || gy <= 0 || gz <= 0 || gx >= h.dims.x() ||
                                  gy >= h.dims.y() || gz >= h.dims.z();
            const Eigen::Vector3d p = latticePoint(gx, gy, gz);
            bs[li] = !boundary && h.insideGiven(p.data(), all, 0, 0);
          }
          bits |= static_cast<std::uint8_t>(bs[li] << c);
        }
        code[s] = bits;
      }
    }
  }

  // Vertex of each voxel the surface crosses: mean of its edges' crossings, each found by
  // bisection with the voxel's own undecided cameras.
  void computeVertices() {
    const std::int64_t n = static_cast<std::int64_t>(h.surface_info.size());
    vertex.assign(n, Eigen::Vector3d::Zero());
#pragma omp parallel for schedule(dynamic, 256) num_threads(threads)
    for (std::int64_t s = 0; s < n; ++s) {
      if (code[s] == 0 || code[s] == 255) continue;
      const detail::SurfaceInfo& info = h.surface_info[s];
      const std::uint64_t* mixed = h.surfaceMixed(s);
      const auto& v = h.surface_voxel[s];
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      int count = 0;
      for (int c = 0; c < 8; ++c) {
        for (int a = 0; a < 3; ++a) {
          const int c2 = c | (1 << a);
          if (c2 == c || cornerInside(s, c) == cornerInside(s, c2)) continue;
          Eigen::Vector3d in = latticePoint(v.x() + (c & 1), v.y() + ((c >> 1) & 1), v.z() + (c >> 2));
          Eigen::Vector3d out =
              latticePoint(v.x() + (c2 & 1), v.y() + ((c2 >> 1) & 1), v.z() + (c2 >> 2));
          if (!cornerInside(s, c)) std::swap(in, out);
          for (int it = 0; it < kRefineIterations; ++it) {
            const Eigen::Vector3d mid = 0.5 * (in + out);
            (h.insideGiven(mid.data(), mixed, info.n_out, info.n_in) ? in : out) = mid;
          }
          sum += 0.5 * (in + out);
          ++count;
        }
      }
      vertex[s] = sum / count;
    }
  }

  bool hasVertex(std::int64_t s) const { return code[s] != 0 && code[s] != 255; }

  // One quad per lattice edge the surface crosses, owned by the voxel at its low corner in the
  // two other axes; wound counter-clockwise seen from the outside end of the edge.
  std::vector<Eigen::Vector3i> faces(long long* anomalies) const {
    const std::int64_t n = static_cast<std::int64_t>(h.surface_info.size());
    std::vector<std::vector<Eigen::Vector3i>> per_thread(threads);
    long long bad = 0;
#pragma omp parallel num_threads(threads) reduction(+ : bad)
    {
      std::vector<Eigen::Vector3i>& out = per_thread[omp_get_thread_num()];
#pragma omp for schedule(static)
      for (std::int64_t s = 0; s < n; ++s) {
        if (!hasVertex(s)) continue;
        const auto& v = h.surface_voxel[s];
        // Per axis: the edge's two corners and the 4 voxels around it (offsets from v) in
        // counter-clockwise order seen from +axis.
        static const int kLow[3] = {6, 5, 3};
        static const int kAround[3][4][3] = {
            {{0, 0, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1}},
            {{0, 0, 0}, {0, 0, 1}, {1, 0, 1}, {1, 0, 0}},
            {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}};
        for (int a = 0; a < 3; ++a) {
          const bool low_in = cornerInside(s, kLow[a]), high_in = cornerInside(s, 7);
          if (low_in == high_in) continue;
          std::int64_t ids[4];
          bool ok = true;
          for (int q = 0; q < 4 && ok; ++q) {
            const int* o = kAround[a][q];
            ok = h.voxelKind(v.x() + o[0], v.y() + o[1], v.z() + o[2], &ids[q]) ==
                     detail::kVoxelSurface &&
                 hasVertex(ids[q]);
          }
          if (!ok) {
            ++bad;
            continue;
          }
          if (!low_in) std::swap(ids[1], ids[3]);  // outward normal is -axis: reverse
          // Split along the shorter diagonal.
          const double d02 = (vertex[ids[0]] - vertex[ids[2]]).squaredNorm();
          const double d13 = (vertex[ids[1]] - vertex[ids[3]]).squaredNorm();
          auto tri = [&](int i, int j, int k) {
            out.emplace_back(static_cast<int>(ids[i]), static_cast<int>(ids[j]),
                             static_cast<int>(ids[k]));
          };
          if (d02 <= d13) {
            tri(0, 1, 2);
            tri(0, 2, 3);
          } else {
            tri(0, 1, 3);
            tri(1, 2, 3);
          }
        }
      }
    }
    *anomalies = bad;
    std::vector<Eigen::Vector3i> all;
    for (auto& f : per_thread) all.insert(all.end(), f.begin(), f.end());
    return all;
  }
};

// Taubin smoothing over the mesh's vertex neighbours.
void smooth(std::vector<Eigen::Vector3d>& p, const std::vector<Eigen::Vector3i>& faces,
            int threads) {
  const int n = static_cast<int>(p.size());
  std::vector<int> start(n + 1, 0), adj;
  for (const auto& f : faces)
    for (int i = 0; i < 3; ++i) start[f[i] + 1] += 2;
  for (int i = 0; i < n; ++i) start[i + 1] += start[i];
  adj.resize(start[n]);
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (const auto& f : faces)
    for (int i = 0; i < 3; ++i) {
      adj[fill[f[i]]++] = f[(i + 1) % 3];
      adj[fill[f[i]]++] = f[(i + 2) % 3];
    }
  std::vector<Eigen::Vector3d> next(n);
  for (int it = 0; it < 2 * kSmoothPairs; ++it) {
    const double w = it % 2 == 0 ? kTaubinLambda : kTaubinMu;
#pragma omp parallel for schedule(static) num_threads(threads)
    for (int i = 0; i < n; ++i) {
      if (start[i + 1] == start[i]) {
        next[i] = p[i];
        continue;
      }
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (int j = start[i]; j < start[i + 1]; ++j) mean += p[adj[j]];
      mean /= start[i + 1] - start[i];
      next[i] = p[i] + w * (mean - p[i]);
    }
    p.swap(next);
  }
}

}  // namespace

TriangleMesh Carver::mesh(const VisualHull& hull) const {
  TriangleMesh mesh;
  if (!hull.data || hull.data->surface_info.empty()) return mesh;
  MeshBuilder b{*hull.data, resolveThreads(impl_->options.threads), {}, {}, {}, {}};
  b.computeSigns();
  b.computeVertices();
  long long anomalies = 0;
  std::vector<Eigen::Vector3i> faces = b.faces(&anomalies);
  // Keep only the vertices of voxels the surface crosses, in surface order.
  const std::int64_t n = static_cast<std::int64_t>(b.vertex.size());
  std::vector<int> id(n, -1);
  std::vector<Eigen::Vector3d> p;
  for (std::int64_t s = 0; s < n; ++s)
    if (b.hasVertex(s)) {
      id[s] = static_cast<int>(p.size());
      p.push_back(b.vertex[s]);
    }
  for (auto& f : faces)
    for (int i = 0; i < 3; ++i) f[i] = id[f[i]];
  smooth(p, faces, b.threads);
  std::vector<Eigen::Vector3d> normal(p.size(), Eigen::Vector3d::Zero());
  for (const auto& f : faces) {
    const Eigen::Vector3d nf = (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]);  // area-weighted
    for (int i = 0; i < 3; ++i) normal[f[i]] += nf;
  }
  mesh.vertices.resize(p.size());
  mesh.normals.resize(p.size());
  for (size_t i = 0; i < p.size(); ++i) {
    mesh.vertices[i] = p[i].cast<float>();
    const double len = normal[i].norm();
    mesh.normals[i] =
        len > 0 ? Eigen::Vector3f((normal[i] / len).cast<float>()) : Eigen::Vector3f::UnitZ();
  }
  mesh.faces = std::move(faces);
  return mesh;
}

}  // namespace previz::carving
