// Surface point clouds: outward normals on a sphere, and the PLY / PCD files read back with
// pcl::io (carving/pointcloud.h).
#include "carving/pointcloud.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "core/error.h"
#include "core/mesh.h"
#include "scratch.h"

namespace previz::carving {
namespace {

// A UV sphere (radius r, centre c) with faces counter-clockwise seen from outside and no normals.
TriangleMesh uvSphere(double r, const Eigen::Vector3f& c, int rings, int segments) {
  TriangleMesh mesh;
  mesh.vertices.push_back(c + Eigen::Vector3f(0, 0, static_cast<float>(r)));
  for (int i = 1; i < rings; ++i) {
    const double theta = M_PI * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double phi = 2 * M_PI * j / segments;
      mesh.vertices.push_back(c + Eigen::Vector3d(r * std::sin(theta) * std::cos(phi),
                                                  r * std::sin(theta) * std::sin(phi),
                                                  r * std::cos(theta)).cast<float>());
    }
  }
  mesh.vertices.push_back(c - Eigen::Vector3f(0, 0, static_cast<float>(r)));
  const int south = static_cast<int>(mesh.vertices.size()) - 1;
  auto ring = [&](int i, int j) { return 1 + (i - 1) * segments + (j % segments); };
  for (int j = 0; j < segments; ++j) mesh.faces.emplace_back(0, ring(1, j), ring(1, j + 1));
  for (int i = 1; i + 1 < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      mesh.faces.emplace_back(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
      mesh.faces.emplace_back(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
    }
  }
  for (int j = 0; j < segments; ++j)
    mesh.faces.emplace_back(south, ring(rings - 1, j + 1), ring(rings - 1, j));
  return mesh;
}

const Eigen::Vector3f kCentre(0.3f, -0.2f, 1.1f);
constexpr double kRadius = 0.25;

// Angle (degrees) between each normal and the true outward radial direction; worst case.
double worstNormalErrorDeg(const SurfacePoints& cloud) {
  double worst = 0;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f radial = (cloud.points[i] - kCentre).normalized();
    const double c = std::clamp<double>(cloud.normals[i].normalized().dot(radial), -1.0, 1.0);
    worst = std::max(worst, std::acos(c) * 180.0 / M_PI);
  }
  return worst;
}

TEST(PointCloud, MeshNormalsPointOutwardOnSphere) {
  const TriangleMesh mesh = uvSphere(kRadius, kCentre, 24, 48);
  const SurfacePoints cloud = surfacePoints(mesh);
  ASSERT_EQ(cloud.size(), mesh.vertices.size());
  // Area-weighted face normals of a 24 x 48 UV sphere lean at most a few degrees off radial
  // (the facets are 7.5 degrees wide); an inward normal would be 180.
  EXPECT_LT(worstNormalErrorDeg(cloud), 5.0);
}

TEST(PointCloud, FaceSamplesAreOnTheSurfaceAndDenseEnough) {
  const TriangleMesh mesh = uvSphere(kRadius, kCentre, 12, 24);  // edges up to ~6.5 cm
  PointCloudOptions options;
  options.spacing_m = 0.01;
  const SurfacePoints cloud = surfacePoints(mesh, options);
  ASSERT_GT(cloud.size(), mesh.vertices.size() * 20);
  // Samples lie on the flat facets: never outside the sphere, and inside by at most
  // r - sqrt(r^2 - rho^2) for the facets' largest circumradius rho (~4.6 cm on the
  // 15 x 15 degree quads' diagonal halves: 4.3 mm).
  for (const Eigen::Vector3f& p : cloud.points) {
    const double d = (p - kCentre).norm();
    ASSERT_LE(d, kRadius + 1e-5);
    ASSERT_GE(d, kRadius - 0.0045);
  }
  EXPECT_LT(worstNormalErrorDeg(cloud), 12.0);  // interpolated vertex normals, outward
  // Coverage: points on the true sphere all lie within ~spacing of a sample.
  double worst_gap = 0;
  for (int i = 0; i < 200; ++i) {
    const double z = -1 + 2 * (i + 0.5) / 200, phi = i * 2.399963;  // Fibonacci sphere
    const Eigen::Vector3f q = kCentre + (kRadius * Eigen::Vector3d(std::sqrt(1 - z * z) * std::cos(phi),
                                                                  std::sqrt(1 - z * z) * std::sin(phi), z))
                                            .cast<float>();
    double best = 1e9;
    for (const Eigen::Vector3f& p : cloud.points) best = std::min<double>(best, (p - q).norm());
    worst_gap = std::max(worst_gap, best);
  }
  EXPECT_LT(worst_gap, 0.012);
}

TEST(PointCloud, EstimatedNormalsPointOutwardOnSphere) {
  const TriangleMesh mesh = uvSphere(kRadius, kCentre, 24, 48);
  PointCloudOptions options;
  options.estimate_normals = true;
  options.spacing_m = 0.02;
  const SurfacePoints cloud = surfacePoints(mesh, options);
  // PCA over 16 neighbours on a 25 cm sphere sampled every ~2 cm: a few degrees off radial.
  EXPECT_LT(worstNormalErrorDeg(cloud), 10.0);
}

TEST(PointCloud, InsideTestOrientsBarePoints) {
  const TriangleMesh mesh = uvSphere(kRadius, kCentre, 24, 48);
  auto inside = [](const Eigen::Vector3d& p) { return (p - kCentre.cast<double>()).norm() < kRadius; };
  const SurfacePoints cloud = orientedNormals(mesh.vertices, inside, 0.01);
  ASSERT_EQ(cloud.size(), mesh.vertices.size());
  EXPECT_LT(worstNormalErrorDeg(cloud), 10.0);
}

TEST(PointCloud, PlyAndPcdReadBackWithPcl) {
  const auto dir = test::scratchDir("carving_pointcloud", "readback");
  const SurfacePoints cloud = surfacePoints(uvSphere(kRadius, kCentre, 16, 32));
  writePointCloudPly(cloud, dir / "points.ply");
  writePointCloudPcd(cloud, dir / "points.pcd");
  for (const char* name : {"points.ply", "points.pcd"}) {
    SCOPED_TRACE(name);
    const SurfacePoints back = readPointCloud(dir / name);
    ASSERT_EQ(back.size(), cloud.size());
    for (size_t i = 0; i < cloud.size(); ++i) {  // binary float: exact
      ASSERT_EQ(back.points[i], cloud.points[i]) << i;
      ASSERT_EQ(back.normals[i], cloud.normals[i]) << i;
    }
  }
  // The header says what the numbers mean, and nothing temporary is left beside the files.
  std::ifstream ply(dir / "points.ply", std::ios::binary);
  std::stringstream header;
  header << ply.rdbuf();
  EXPECT_NE(header.str().find("comment previz surface points: world frame, metres"), std::string::npos);
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    (void)entry;
    ++files;
  }
  EXPECT_EQ(files, 2);
}

TEST(PointCloud, EmptyCloudWritesAndReadsBack) {
  const auto dir = test::scratchDir("carving_pointcloud", "empty");
  writePointCloudPly(SurfacePoints{}, dir / "e.ply");
  writePointCloudPcd(SurfacePoints{}, dir / "e.pcd");
  EXPECT_EQ(readPointCloud(dir / "e.pcd").size(), 0u);
  EXPECT_EQ(readPointCloud(dir / "e.ply").size(), 0u);
}

TEST(PointCloud, BadInputNamesTheCulprit) {
  PointCloudOptions options;
  options.spacing_m = -1;
  try {
    surfacePoints(uvSphere(kRadius, kCentre, 8, 8), options);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "spacing_m");
  }
  const auto dir = test::scratchDir("carving_pointcloud", "bad");
  try {
    readPointCloud(dir / "missing.pcd");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(e.context().file.find("missing.pcd"), std::string::npos);
  }
}

}  // namespace
}  // namespace previz::carving
