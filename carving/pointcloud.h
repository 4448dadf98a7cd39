#pragma once
// The hull's surface as a point cloud with outward normals, for post (PLY / PCD through PCL).
// Points come from a TriangleMesh (its vertices, plus samples on its faces when a spacing is
// asked for) or from any surface point set with an inside test that orients the normals.
// World frame, metres, z up (docs/conventions.md). PCL stays inside the previz_pointcloud plugin
// (detail/pointcloud_plugin.h), loaded only when a cloud is written, read or its normals estimated.
#include <filesystem>
#include <functional>
#include <vector>

#include <Eigen/Core>

#include "core/mesh.h"

namespace previz::carving {

struct PointCloudOptions {
  // > 0: besides the vertices, each face gets samples so that no point of the surface is
  // farther than about this from a sample (area-weighted, deterministic); 0 = vertices only.
  double spacing_m = 0;
  // false: normals interpolated from the mesh's vertex normals (face normals when the mesh has
  // none). true: PCL NormalEstimation (PCA over the k nearest points), each normal turned to
  // agree with the mesh's side (or the inside test) — what a scan-based tool would give.
  bool estimate_normals = false;
  int normal_neighbours = 16;
  void validate() const;  // throws Error naming the field
};

struct SurfacePoints {
  std::vector<Eigen::Vector3f> points;   // world, metres
  std::vector<Eigen::Vector3f> normals;  // unit, outward; same size as points
  size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
};

// Points and outward normals on a mesh (faces counter-clockwise seen from outside, core/mesh.h).
SurfacePoints surfacePoints(const TriangleMesh& mesh, const PointCloudOptions& options = {});

// Normals for a bare point set (e.g. hull surface cell centres) by PCL NormalEstimation, each
// turned outward: 'inside' is the solid's point test (e.g. Carver::inside); the normal is flipped
// when p + probe_m * n is inside and p - probe_m * n is not.
SurfacePoints orientedNormals(const std::vector<Eigen::Vector3f>& points,
                              const std::function<bool(const Eigen::Vector3d&)>& inside,
                              double probe_m, int neighbours = 16);

// Writers through pcl::io (binary; pcl::PointNormal: x y z normal_x normal_y normal_z
// curvature), atomically, with a header comment stating units and frame. Errors name the file.
void writePointCloudPly(const SurfacePoints& cloud, const std::filesystem::path& path);
void writePointCloudPcd(const SurfacePoints& cloud, const std::filesystem::path& path);
// Reads either (by extension) through pcl::io.
SurfacePoints readPointCloud(const std::filesystem::path& path);

}  // namespace previz::carving
