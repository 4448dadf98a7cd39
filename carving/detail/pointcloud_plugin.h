#pragma once
// The previz_pointcloud plugin (carving/plugin/pointcloud.cpp): every call into PCL behind
// carving/pointcloud.h, loaded the first time a cloud is written, read or its normals estimated
// (core/plugin.h): PCL's io brings 67 shared libraries (VTK among them), which a carve that
// writes no point cloud need not load.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "carving/pointcloud.h"

namespace previz::carving::detail {

struct PointCloudPlugin {
  static constexpr int kVersion = 1;
  int version = kVersion;
  // PCA normals over the k nearest points (pcl::NormalEstimation, KdTree search), unoriented;
  // NaN where PCL finds too few neighbours.
  std::vector<Eigen::Vector3f> (*pca_normals)(const std::vector<Eigen::Vector3f>& points, int k) = nullptr;
  // 'cloud' (as many normals as points; curvature 0) written to 'file' by pcl::PLYWriter (binary)
  // or pcl::io::savePCDFile (binary; ASCII when empty, PCL refuses a binary empty cloud); PCL's
  // return code (0 = written). PCL's exceptions pass through.
  int (*write_ply)(const std::string& file, const SurfacePoints& cloud) = nullptr;
  int (*write_pcd)(const std::string& file, const SurfacePoints& cloud) = nullptr;
  // pcl::io::loadPCDFile / loadPLYFile into 'cloud'; PCL's return code (< 0 = failed).
  int (*read_pcd)(const std::string& file, SurfacePoints& cloud) = nullptr;
  int (*read_ply)(const std::string& file, SurfacePoints& cloud) = nullptr;
};

}  // namespace previz::carving::detail
