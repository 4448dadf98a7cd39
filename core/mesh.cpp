// Triangle mesh files (docs/formats.md "Meshes"): binary little-endian PLY and OBJ with vertex
// normals, world frame, metres, z up.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/io.h"
#include "core/mesh.h"

namespace previz {

namespace {

void checkMesh(const TriangleMesh& mesh, const std::filesystem::path& path) {
  ErrorContext context;
  context.file = path.string();
  if (mesh.normals.size() != mesh.vertices.size())
    throw Error("mesh: " + std::to_string(mesh.normals.size()) + " normals for " +
                    std::to_string(mesh.vertices.size()) + " vertices",
                context);
  const auto n = static_cast<int>(mesh.vertices.size());
  for (const auto& f : mesh.faces)
    for (int k = 0; k < 3; ++k)
      if (f[k] < 0 || f[k] >= n)
        throw Error("mesh: face index " + std::to_string(f[k]) + " out of range (" +
                        std::to_string(n) + " vertices)",
                    context);
}

void putU32(std::string& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void putF32(std::string& out, float f) {
  std::uint32_t v;
  std::memcpy(&v, &f, 4);
  putU32(out, v);
}
std::uint32_t getU32(const unsigned char* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
float getF32(const unsigned char* p) {
  const std::uint32_t v = getU32(p);
  float f;
  std::memcpy(&f, &v, 4);
  return f;
}

}  // namespace

void writePly(const TriangleMesh& mesh, const std::filesystem::path& path,
              const std::string& world_frame) {
  checkMesh(mesh, path);
  std::ostringstream header;
  header << "ply\n"
         << "format binary_little_endian 1.0\n"
         << "comment previz mesh: units metres, " << world_frame << "\n"
         << "element vertex " << mesh.vertices.size() << "\n"
         << "property float x\nproperty float y\nproperty float z\n"
         << "property float nx\nproperty float ny\nproperty float nz\n"
         << "element face " << mesh.faces.size() << "\n"
         << "property list uchar int vertex_indices\n"
         << "end_header\n";
  std::string out = header.str();
  out.reserve(out.size() + mesh.vertices.size() * 24 + mesh.faces.size() * 13);
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    for (int k = 0; k < 3; ++k) putF32(out, mesh.vertices[i][k]);
    for (int k = 0; k < 3; ++k) putF32(out, mesh.normals[i][k]);
  }
  for (const auto& f : mesh.faces) {
    out.push_back(3);
    for (int k = 0; k < 3; ++k) putU32(out, static_cast<std::uint32_t>(f[k]));
  }
  writeFileAtomic(path, out);
}

void writeObj(const TriangleMesh& mesh, const std::filesystem::path& path,
              const std::string& world_frame) {
  checkMesh(mesh, path);
  std::string out;
  out.reserve(mesh.vertices.size() * 80 + mesh.faces.size() * 40 + 256);
  out += "# previz mesh: units metres, " + world_frame + "\n";
  out += "# " + std::to_string(mesh.vertices.size()) + " vertices, " +
         std::to_string(mesh.faces.size()) + " faces\n";
  char line[160];
  for (const auto& v : mesh.vertices) {
    std::snprintf(line, sizeof(line), "v %.7g %.7g %.7g\n", v.x(), v.y(), v.z());
    out += line;
  }
  for (const auto& n : mesh.normals) {
    std::snprintf(line, sizeof(line), "vn %.6g %.6g %.6g\n", n.x(), n.y(), n.z());
    out += line;
  }
  for (const auto& f : mesh.faces) {
    std::snprintf(line, sizeof(line), "f %d//%d %d//%d %d//%d\n", f[0] + 1, f[0] + 1, f[1] + 1,
                  f[1] + 1, f[2] + 1, f[2] + 1);
    out += line;
  }
  writeFileAtomic(path, out);
}

TriangleMesh readPly(const std::filesystem::path& path) {
  const std::string bytes = readTextFile(path);  // binary-safe: whole file into a string
  ErrorContext context;
  context.file = path.string();
  auto fail = [&](const std::string& what) { return Error("ply: " + what, context); };

  const std::string end_marker = "end_header\n";
  const size_t end = bytes.find(end_marker);
  if (bytes.compare(0, 4, "ply\n") != 0) throw fail("not a PLY file (missing 'ply' magic)");
  if (end == std::string::npos) throw fail("missing end_header");
  std::istringstream header(bytes.substr(0, end));
  std::string line;
  long long vertices = -1, faces = -1;
  std::vector<std::string> vertex_props;
  std::string current;
  bool format_ok = false, face_list_ok = false;
  while (std::getline(header, line)) {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      std::string fmt, version;
      ls >> fmt >> version;
      if (fmt != "binary_little_endian") throw fail("unsupported format '" + fmt + "' (expected binary_little_endian)");
      format_ok = true;
    } else if (word == "element") {
      std::string name;
      long long count = -1;
      ls >> name >> count;
      if (count < 0) throw fail("bad element count in '" + line + "'");
      current = name;
      if (name == "vertex") vertices = count;
      else if (name == "face") faces = count;
      else throw fail("unexpected element '" + name + "'");
    } else if (word == "property") {
      std::string type;
      ls >> type;
      if (current == "vertex") {
        std::string name;
        ls >> name;
        if (type != "float") throw fail("vertex property '" + name + "' must be float");
        vertex_props.push_back(name);
      } else if (current == "face") {
        std::string count_type, index_type, name;
        ls >> count_type >> index_type >> name;
        if (type != "list" || count_type != "uchar" || (index_type != "int" && index_type != "uint"))
          throw fail("face property must be 'list uchar int' (got '" + line + "')");
        face_list_ok = true;
      }
    }
  }
  if (!format_ok) throw fail("missing format line");
  if (vertices < 0 || faces < 0) throw fail("missing vertex or face element");
  const std::vector<std::string> expected = {"x", "y", "z", "nx", "ny", "nz"};
  if (vertex_props != expected) throw fail("vertex properties must be x y z nx ny nz");
  if (!face_list_ok) throw fail("missing face vertex_indices list");

  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data()) + end + end_marker.size();
  const auto* stop = reinterpret_cast<const unsigned char*>(bytes.data()) + bytes.size();
  const auto vertex_bytes = static_cast<unsigned long long>(vertices) * 24ull;
  if (static_cast<unsigned long long>(stop - p) < vertex_bytes) throw fail("truncated vertex data");
  TriangleMesh mesh;
  mesh.vertices.resize(static_cast<size_t>(vertices));
  mesh.normals.resize(static_cast<size_t>(vertices));
  for (long long i = 0; i < vertices; ++i, p += 24) {
    mesh.vertices[i] = Eigen::Vector3f(getF32(p), getF32(p + 4), getF32(p + 8));
    mesh.normals[i] = Eigen::Vector3f(getF32(p + 12), getF32(p + 16), getF32(p + 20));
  }
  mesh.faces.reserve(static_cast<size_t>(faces));
  for (long long i = 0; i < faces; ++i) {
    if (stop - p < 13) throw fail("truncated face data at face " + std::to_string(i));
    if (*p != 3) throw fail("face " + std::to_string(i) + " is not a triangle");
    Eigen::Vector3i f;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t idx = getU32(p + 1 + 4 * k);
      if (idx >= static_cast<std::uint32_t>(vertices))
        throw fail("face " + std::to_string(i) + " index " + std::to_string(idx) + " out of range");
      f[k] = static_cast<int>(idx);
    }
    mesh.faces.push_back(f);
    p += 13;
  }
  if (p != stop) throw fail("trailing bytes after the face data");
  return mesh;
}

}  // namespace previz
