#pragma once
// Per-frame JSON lines files: a synthetic take's truth/main_poses.jsonl, `previz track camera`'s
// camera_poses.jsonl, truth/props.jsonl. One JSON object a line, each with an integer "frame".
#include <filesystem>
#include <functional>
#include <map>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "core/error.h"
#include "core/pose.h"

namespace previz {

// Every non-empty line of the file, parsed and checked to be an object with an integer "frame"
// and 'key', handed to 'line' with a context naming the file and line. A malformed line, or an
// Error thrown by 'line', is an Error naming them ('expected' says what a line holds).
void forEachFrameLine(const std::filesystem::path& path, const std::string& key, const std::string& expected,
                      const std::function<void(const nlohmann::json&, const ErrorContext&)>& line);

// {"frame", key: {"R", "t"}} lines -> frame -> pose. A line whose "state" is not "tracked"
// (camera_poses.jsonl's "lost" and "bad frame") has no pose: its frame goes to 'unposed' (when
// given) with the line's "reason". Throws Error naming the file and line.
std::map<int, Pose> readPoseLines(const std::filesystem::path& path, const std::string& key = "T_world_cam",
                                  std::map<int, std::string>* unposed = nullptr);

}  // namespace previz
