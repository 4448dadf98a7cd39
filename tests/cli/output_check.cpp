// previz_output_check PATH...: reads every file (and every file under each folder) whole, as the next tool in
// the chain would, and says which are incomplete (scripts/killtest.sh: after a SIGKILL every
// output present must be whole). PNG / JPEG decoded (libpng: every row, every CRC), EXR read
// (every channel), JSON parsed, JSON lines parsed line by line and ended by a newline, PLY read
// (meshes with readPly, point clouds through PCL), PCD through PCL, OBJ's vertex and face
// lines parsed with every index in range. The temporaries an interrupted atomic write leaves
// (".<name>.tmp.<pid>...", ".<name>.pcl.<pid>...") are listed apart: no reader takes them for
// an output. Prints one JSON line {"files", "complete", "incomplete": [{file, why}],
// "temporaries": [...], "unchecked": [...]}; exit 1 when a file is incomplete.
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "carving/pointcloud.h"
#include "core/error.h"
#include "core/io.h"
#include "core/mesh.h"

namespace fs = std::filesystem;
using namespace previz;

namespace {

void checkJsonLines(const fs::path& p) {
  const std::string text = readTextFile(p);
  if (!text.empty() && text.back() != '\n') throw Error("the last line is not ended", fileContext(p));
  std::istringstream in(text);
  int n = 0;
  for (std::string line; std::getline(in, line);) {
    ++n;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    try {
      const nlohmann::json parsed = nlohmann::json::parse(line);  // throws on a bad line
      (void)parsed;
    } catch (const std::exception& e) {
      throw Error(std::string("line ") + std::to_string(n) + ": " + e.what(), fileContext(p));
    }
  }
}

void checkObj(const fs::path& p) {
  const std::string text = readTextFile(p);
  if (text.empty() || text.back() != '\n') throw Error("empty or the last line is not ended", fileContext(p));
  std::istringstream in(text);
  long long vertices = 0, faces = 0;
  for (std::string line; std::getline(in, line);) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v") {
      double x, y, z;
      if (!(ls >> x >> y >> z)) throw Error("a vertex line without 3 numbers: " + line, fileContext(p));
      ++vertices;
    } else if (tag == "f") {
      std::string item;
      int corners = 0;
      while (ls >> item) {
        const long long i = std::stoll(item.substr(0, item.find('/')));
        if (i == 0 || i > vertices || -i > vertices) throw Error("face index out of range: " + line, fileContext(p));
        ++corners;
      }
      if (corners < 3) throw Error("a face with fewer than 3 corners: " + line, fileContext(p));
      ++faces;
    }
  }
}

bool isTemporary(const std::string& name) {
  return name.size() > 1 && name[0] == '.' &&
         (name.find(".tmp.") != std::string::npos || name.find(".pcl.") != std::string::npos);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: previz_output_check PATH...\n";
    return 2;
  }
  nlohmann::json incomplete = nlohmann::json::array(), temporaries = nlohmann::json::array(),
                 unchecked = nlohmann::json::array();
  int files = 0, complete = 0;
  std::vector<fs::path> paths;
  for (int a = 1; a < argc; ++a) {
    if (fs::is_regular_file(argv[a])) {
      paths.push_back(argv[a]);
      continue;
    }
    if (!fs::is_directory(argv[a])) continue;  // not written (yet): nothing to check
    for (const auto& e : fs::recursive_directory_iterator(argv[a]))
      if (e.is_regular_file()) paths.push_back(e.path());
  }
  {
    for (const fs::path& p : paths) {
      const std::string name = p.filename().string();
      if (isTemporary(name)) {
        temporaries.push_back(p.string());
        continue;
      }
      ++files;
      const std::string ext = p.extension().string();
      try {
        if (ext == ".png" || ext == ".jpg") {
          if (readImage(p).empty()) throw Error("decodes to no image", fileContext(p));
        } else if (ext == ".exr") {
          (void)readExr(p);
        } else if (ext == ".json") {
          const nlohmann::json parsed = nlohmann::json::parse(readTextFile(p));  // throws on bad JSON
          (void)parsed;
        } else if (ext == ".jsonl") {
          checkJsonLines(p);
        } else if (ext == ".ply") {
          const std::string head = readTextFile(p).substr(0, 4096);
          // A point cloud (PCL's PLY writes "element face 0") or a mesh.
          const bool points = head.find("element face") == std::string::npos ||
                              head.find("element face 0\n") != std::string::npos;
          if (points) (void)carving::readPointCloud(p);
          else (void)readPly(p);
        } else if (ext == ".pcd") {
          (void)carving::readPointCloud(p);
        } else if (ext == ".obj") {
          checkObj(p);
        } else {
          unchecked.push_back(p.string());
          continue;
        }
        ++complete;
      } catch (const std::exception& ex) {
        incomplete.push_back({{"file", p.string()}, {"why", ex.what()}});
      }
    }
  }
  std::cout << nlohmann::json{{"files", files}, {"complete", complete}, {"incomplete", incomplete},
                              {"temporaries", temporaries}, {"unchecked", unchecked}}
                   .dump()
            << "\n";
  return incomplete.empty() ? 0 : 1;
}
