#include "core/pose_lines.h"

#include <sstream>

#include <nlohmann/json.hpp>

#include "core/io.h"

namespace previz {

void forEachFrameLine(const std::filesystem::path& path, const std::string& key, const std::string& expected,
                      const std::function<void(const nlohmann::json&, const ErrorContext&)>& line_fn) {
  std::istringstream in(readTextFile(path));
  int line_no = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    ErrorContext c;
    c.file = path.string();
    c.field = "line " + std::to_string(line_no);
    const nlohmann::json j = nlohmann::json::parse(line, nullptr, false);
    // A frame beyond int (99999999999) came out wrapped from get<int>() (fuzz/pose_lines.cpp).
    if (j.is_discarded() || !j.is_object() || !j.contains("frame") || !j["frame"].is_number_integer() ||
        !jsonInt(j["frame"]) || !j.contains(key))
      throw Error("expected " + expected, c);
    try {
      line_fn(j, c);
    } catch (const Error& e) {
      throw Error(e.message(), c);
    }
  }
}

std::map<int, Pose> readPoseLines(const std::filesystem::path& path, const std::string& key,
                                  std::map<int, std::string>* unposed) {
  std::map<int, Pose> out;
  const std::string expected = "{\"frame\": integer, \"" + key + "\": {\"R\", \"t\"}} or {\"frame\", \"state\"}";
  forEachFrameLine(path, "frame", expected, [&](const nlohmann::json& j, const ErrorContext& c) {
    const int frame = j["frame"].get<int>();
    if (j.contains("state") && !(j["state"].is_string() && j["state"].get<std::string>() == "tracked")) {
      if (unposed) {
        const auto reason = j.find("reason");
        (*unposed)[frame] = reason != j.end() && reason->is_string() ? reason->get<std::string>()
                                                                     : "state " + j["state"].dump();
      }
      return;
    }
    if (!j.contains(key)) throw Error("expected " + expected, c);
    out[frame] = poseFromJson(j[key], key);
  });
  return out;
}

}  // namespace previz
