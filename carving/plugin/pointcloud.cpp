// The previz_pointcloud plugin: PCL behind carving/pointcloud.cpp (detail/pointcloud_plugin.h).
#include <algorithm>
#include <cstdint>

#include <pcl/conversions.h>
#include <pcl/features/normal_3d.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include "carving/detail/pointcloud_plugin.h"
#include "core/plugin.h"

namespace previz::carving {
namespace {

std::vector<Eigen::Vector3f> pcaNormals(const std::vector<Eigen::Vector3f>& points, int k) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  cloud->resize(points.size());
  for (size_t i = 0; i < points.size(); ++i) (*cloud)[i].getVector3fMap() = points[i];
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> estimator;
  estimator.setInputCloud(cloud);
  pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
  estimator.setSearchMethod(tree);
  estimator.setKSearch(std::min<int>(k, static_cast<int>(points.size())));
  pcl::PointCloud<pcl::Normal> normals;
  estimator.compute(normals);
  std::vector<Eigen::Vector3f> out(points.size());
  for (size_t i = 0; i < points.size(); ++i) out[i] = normals[i].getNormalVector3fMap();
  return out;
}

pcl::PointCloud<pcl::PointNormal> toPcl(const SurfacePoints& cloud) {
  pcl::PointCloud<pcl::PointNormal> out;
  out.resize(cloud.points.size());
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    out[i].getVector3fMap() = cloud.points[i];
    out[i].getNormalVector3fMap() = cloud.normals[i];
    out[i].curvature = 0;
  }
  out.width = static_cast<std::uint32_t>(out.size());
  out.height = 1;
  out.is_dense = true;
  return out;
}

SurfacePoints fromPcl(const pcl::PointCloud<pcl::PointNormal>& pc) {
  SurfacePoints out;
  out.points.reserve(pc.size());
  out.normals.reserve(pc.size());
  for (const pcl::PointNormal& p : pc) {
    out.points.push_back(p.getVector3fMap());
    out.normals.push_back(p.getNormalVector3fMap());
  }
  return out;
}

int writePly(const std::string& file, const SurfacePoints& cloud) {
  pcl::PLYWriter writer;
  return writer.write(file, toPcl(cloud), /*binary=*/true, /*use_camera=*/false);
}

int writePcd(const std::string& file, const SurfacePoints& cloud) {
  const pcl::PointCloud<pcl::PointNormal> pc = toPcl(cloud);
  return pc.empty() ? pcl::io::savePCDFileASCII(file, pc) : pcl::io::savePCDFileBinary(file, pc);
}

// The points of a file read as PCL's untyped blob. PCL 1.13's fromPCLPointCloud2 takes &cloud[0]
// even of an empty cloud (undefined behaviour; UBSan reports it in the typed loadPCDFile /
// loadPLYFile), so a file without points is not converted: it reads as an empty cloud.
int fromBlob(int rc, const pcl::PCLPointCloud2& blob, SurfacePoints& cloud) {
  if (rc < 0) return rc;
  pcl::PointCloud<pcl::PointNormal> pc;
  if (static_cast<std::uint64_t>(blob.width) * blob.height > 0) pcl::fromPCLPointCloud2(blob, pc);
  cloud = fromPcl(pc);
  return rc;
}

int readPcd(const std::string& file, SurfacePoints& cloud) {
  pcl::PCLPointCloud2 blob;
  return fromBlob(pcl::io::loadPCDFile(file, blob), blob, cloud);
}

int readPly(const std::string& file, SurfacePoints& cloud) {
  pcl::PCLPointCloud2 blob;
  return fromBlob(pcl::io::loadPLYFile(file, blob), blob, cloud);
}

const detail::PointCloudPlugin kPlugin{detail::PointCloudPlugin::kVersion, pcaNormals, writePly, writePcd, readPcd,
                                       readPly};

}  // namespace
}  // namespace previz::carving

PREVIZ_PLUGIN_ENTRY const void* previz_pointcloud_plugin(int version) {
  return version == previz::carving::kPlugin.version ? &previz::carving::kPlugin : nullptr;
}
