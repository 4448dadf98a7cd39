// Surface point clouds with normals (see pointcloud.h). PCL's part is the previz_pointcloud
// plugin's (detail/pointcloud_plugin.h), loaded only when a cloud is written, read or its
// normals estimated.
#include "carving/pointcloud.h"

#include <unistd.h>

#include <atomic>
#include <cmath>
#include <sstream>
#include <string>

#include <Eigen/Geometry>

#include "carving/detail/pointcloud_plugin.h"
#include "core/error.h"
#include "core/io.h"
#include "core/plugin.h"

namespace previz::carving {
namespace fs = std::filesystem;

namespace {

const char* kFrameNote = "world frame, metres, z up (previz docs/conventions.md); normals outward";

Eigen::Vector3f faceNormal(const TriangleMesh& mesh, const Eigen::Vector3i& f) {
  const Eigen::Vector3f a = mesh.vertices[f[0]], b = mesh.vertices[f[1]], c = mesh.vertices[f[2]];
  return (b - a).cross(c - a);  // counter-clockwise from outside: points out; length = 2 area
}

// Vertex normals from the faces (area-weighted) when the mesh carries none.
std::vector<Eigen::Vector3f> vertexNormals(const TriangleMesh& mesh) {
  if (mesh.normals.size() == mesh.vertices.size()) return mesh.normals;
  std::vector<Eigen::Vector3f> normals(mesh.vertices.size(), Eigen::Vector3f::Zero());
  for (const Eigen::Vector3i& f : mesh.faces) {
    const Eigen::Vector3f n = faceNormal(mesh, f);
    for (int i = 0; i < 3; ++i) normals[f[i]] += n;
  }
  for (Eigen::Vector3f& n : normals) {
    const float len = n.norm();
    if (len > 0) n /= len;
  }
  return normals;
}

void checkMesh(const TriangleMesh& mesh) {
  const int n = static_cast<int>(mesh.vertices.size());
  for (const Eigen::Vector3i& f : mesh.faces) {
    if (f.minCoeff() < 0 || f.maxCoeff() >= n)
      throw Error("point cloud: mesh face refers to vertex " + std::to_string(f.maxCoeff()) +
                  " of " + std::to_string(n));
  }
}

// Points on the faces: each face split into m x m sub-triangles (m from its longest edge and
// the spacing), one sample at each sub-triangle's centroid — deterministic, none on the edges
// (so shared edges give no duplicates), every surface point within about 'spacing' of one.
void sampleFaces(const TriangleMesh& mesh, const std::vector<Eigen::Vector3f>& vn, double spacing,
                 SurfacePoints& out) {
  for (const Eigen::Vector3i& f : mesh.faces) {
    const Eigen::Vector3f a = mesh.vertices[f[0]], b = mesh.vertices[f[1]], c = mesh.vertices[f[2]];
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int m = static_cast<int>(std::ceil(longest / spacing));
    if (m < 2) continue;  // the vertices already cover it
    const Eigen::Vector3f fn = faceNormal(mesh, f).normalized();
    const float inv = 1.0f / static_cast<float>(m);
    auto emit = [&](float u, float v) {  // barycentric weights of b and c
      const float w = 1.0f - u - v;
      out.points.push_back(w * a + u * b + v * c);
      Eigen::Vector3f n = w * vn[f[0]] + u * vn[f[1]] + v * vn[f[2]];
      n = n.norm() > 1e-6f ? n.normalized() : fn;
      out.normals.push_back(n);
    };
    for (int i = 0; i < m; ++i) {
      for (int j = 0; j + i < m; ++j) {
        emit((i + 1.0f / 3.0f) * inv, (j + 1.0f / 3.0f) * inv);  // upright sub-triangle
        if (i + j + 2 <= m) emit((i + 2.0f / 3.0f) * inv, (j + 2.0f / 3.0f) * inv);  // inverted
      }
    }
  }
}

const detail::PointCloudPlugin& pcl() {
  return pluginInterface<detail::PointCloudPlugin>("previz_pointcloud", "previz_pointcloud_plugin",
                                                   "point clouds: PCL");
}

// PCA normals over the k nearest points (pcl::NormalEstimation). Unoriented: sign arbitrary.
std::vector<Eigen::Vector3f> pcaNormals(const std::vector<Eigen::Vector3f>& points, int k) {
  std::vector<Eigen::Vector3f> out = pcl().pca_normals(points, k);
  for (Eigen::Vector3f& n : out)
    if (!n.allFinite()) n.setZero();  // too few neighbours: NaN from PCL -> zero, reported below
  return out;
}

void checkNormals(const SurfacePoints& cloud) {
  if (cloud.normals.size() != cloud.points.size())
    throw Error("point cloud: " + std::to_string(cloud.points.size()) + " points but " +
                std::to_string(cloud.normals.size()) + " normals");
}

// PCL writes straight to a named file; it goes to a private temporary beside the target, the
// header gets our comment line, and the result is put in place by writeFileAtomic.
template <typename WriteFn>
void writeThroughPcl(const fs::path& path, const std::string& comment_after,
                     const std::string& comment_line, WriteFn&& write) {
  static std::atomic<unsigned long> counter{0};
  std::error_code ec;
  if (!path.parent_path().empty()) fs::create_directories(path.parent_path(), ec);
  const fs::path tmp = path.parent_path() / ("." + path.filename().string() + ".pcl." +
                                             std::to_string(::getpid()) + "." +
                                             std::to_string(counter.fetch_add(1)));
  int rc = -1;
  try {
    rc = write(tmp.string());
  } catch (const std::exception& e) {
    fs::remove(tmp, ec);
    throw Error(std::string("point cloud: PCL could not write: ") + e.what(), fileContext(path));
  }
  if (rc != 0) {
    fs::remove(tmp, ec);
    throw Error("point cloud: PCL could not write (code " + std::to_string(rc) + ")",
                fileContext(path));
  }
  std::string bytes;
  try {
    bytes = readTextFile(tmp);
  } catch (...) {
    fs::remove(tmp, ec);
    throw;
  }
  fs::remove(tmp, ec);
  const size_t at = bytes.find(comment_after);
  if (at != std::string::npos) {
    const size_t eol = bytes.find('\n', at);
    if (eol != std::string::npos) bytes.insert(eol + 1, comment_line + "\n");
  }
  writeFileAtomic(path, bytes);
}

}  // namespace

void PointCloudOptions::validate() const {
  ErrorContext context;
  if (!(spacing_m >= 0) || !std::isfinite(spacing_m)) {
    context.field = "spacing_m";
    throw Error("point cloud: spacing_m must be >= 0 (got " + std::to_string(spacing_m) + ")",
                context);
  }
  if (normal_neighbours < 3) {
    context.field = "normal_neighbours";
    throw Error("point cloud: normal_neighbours must be >= 3 (got " +
                    std::to_string(normal_neighbours) + ")",
                context);
  }
}

SurfacePoints surfacePoints(const TriangleMesh& mesh, const PointCloudOptions& options) {
  options.validate();
  checkMesh(mesh);
  SurfacePoints out;
  if (mesh.vertices.empty()) return out;
  const std::vector<Eigen::Vector3f> vn = vertexNormals(mesh);
  out.points = mesh.vertices;
  out.normals = vn;
  if (options.spacing_m > 0) sampleFaces(mesh, vn, options.spacing_m, out);
  if (options.estimate_normals && out.size() >= 3) {
    // The mesh's side decides each PCA normal's sign: PCA alone cannot tell out from in.
    const std::vector<Eigen::Vector3f> pca = pcaNormals(out.points, options.normal_neighbours);
    for (size_t i = 0; i < out.size(); ++i) {
      if (pca[i].squaredNorm() == 0) continue;  // degenerate neighbourhood: keep the mesh's
      out.normals[i] = pca[i].dot(out.normals[i]) < 0 ? Eigen::Vector3f(-pca[i]) : pca[i];
    }
  }
  return out;
}

SurfacePoints orientedNormals(const std::vector<Eigen::Vector3f>& points,
                              const std::function<bool(const Eigen::Vector3d&)>& inside,
                              double probe_m, int neighbours) {
  if (neighbours < 3) {
    ErrorContext context;
    context.field = "neighbours";
    throw Error("point cloud: neighbours must be >= 3", context);
  }
  SurfacePoints out;
  out.points = points;
  if (points.size() < 3) {
    out.normals.assign(points.size(), Eigen::Vector3f::Zero());
    return out;
  }
  out.normals = pcaNormals(points, neighbours);
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d p = points[i].cast<double>();
    const Eigen::Vector3d n = out.normals[i].cast<double>();
    if (n.squaredNorm() == 0) continue;
    if (inside(p + probe_m * n) && !inside(p - probe_m * n)) out.normals[i] = -out.normals[i];
  }
  return out;
}

void writePointCloudPly(const SurfacePoints& cloud, const fs::path& path) {
  checkNormals(cloud);
  if (cloud.empty()) {
    // PCL refuses to write a cloud without points; an empty hull still gets its file (the
    // header PCL would write, no vertices), so a finished frame always has every output.
    writeFileAtomic(path, std::string("ply\nformat binary_little_endian 1.0\ncomment previz surface "
                                      "points: ") + kFrameNote +
                              "\nelement vertex 0\nproperty float x\nproperty float y\n"
                              "property float z\nproperty float normal_x\nproperty float normal_y\n"
                              "property float normal_z\nproperty float curvature\nend_header\n");
    return;
  }
  writeThroughPcl(path, "format ", std::string("comment previz surface points: ") + kFrameNote,
                  [&](const std::string& file) { return pcl().write_ply(file, cloud); });
}

void writePointCloudPcd(const SurfacePoints& cloud, const fs::path& path) {
  checkNormals(cloud);
  writeThroughPcl(path, "# .PCD", std::string("# previz surface points: ") + kFrameNote,
                  [&](const std::string& file) { return pcl().write_pcd(file, cloud); });
}

SurfacePoints readPointCloud(const fs::path& path) {
  if (!fs::exists(path)) throw Error("point cloud: no such file", fileContext(path));
  const std::string ext = path.extension().string();
  SurfacePoints out;
  int rc = -1;
  if (ext == ".pcd" || ext == ".PCD") {
    rc = pcl().read_pcd(path.string(), out);
  } else if (ext == ".ply" || ext == ".PLY") {
    rc = pcl().read_ply(path.string(), out);
  } else {
    throw Error("point cloud: unknown extension '" + ext + "' (expected .ply or .pcd)",
                fileContext(path));
  }
  if (rc < 0) throw Error("point cloud: PCL could not read the file", fileContext(path));
  return out;
}

}  // namespace previz::carving
