#pragma once
// Triangle meshes (world frame, metres, z up) and their files: binary little-endian PLY and OBJ
// with vertex normals. The synthetic studio writes its true actor meshes with these; carving
// writes the carved hull with them.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace previz {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;  // world, metres
  std::vector<Eigen::Vector3f> normals;   // per vertex, unit (may be empty)
  std::vector<Eigen::Vector3i> faces;     // counter-clockwise seen from outside
};

// Atomic writers; readPly reads binary little-endian PLY as writePly writes it. Errors name
// the file.
// 'world_frame' is the header comment's frame note (batch/collect writes a y-up variant).
void writePly(const TriangleMesh& mesh, const std::filesystem::path& path,
              const std::string& world_frame = "world frame z up (floor z = 0)");
void writeObj(const TriangleMesh& mesh, const std::filesystem::path& path,
              const std::string& world_frame = "world frame z up (floor z = 0)");
TriangleMesh readPly(const std::filesystem::path& path);

}  // namespace previz
