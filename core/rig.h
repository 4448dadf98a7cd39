#pragma once
// A rig: named cameras with intrinsics and their pose in one world frame (z up, metres).
// rig.json is the format every stage of previz reads; see docs/formats.md.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/camera.h"
#include "core/pose.h"

namespace previz {

struct RigCamera {
  Camera camera;
  Pose T_world_cam = Pose::Identity();
  std::string role = "witness";  // "witness" | "main"
};

struct Rig {
  std::vector<RigCamera> cameras;
  std::string units = "m";
  std::string world_frame = "z up, floor at z = 0";

  const RigCamera* find(const std::string& name) const;
  // Throws Error naming the camera when absent.
  const RigCamera& at(const std::string& name) const;
  RigCamera& at(const std::string& name);
  std::vector<std::string> names() const;
  // Throws when two cameras share a name or a camera is invalid.
  void validate() const;
};

nlohmann::json cameraToJson(const Camera& camera);
Camera cameraFromJson(const nlohmann::json& j, const std::string& file = {});
nlohmann::json rigToJson(const Rig& rig);
Rig rigFromJson(const nlohmann::json& j, const std::string& file = {});

// File I/O; read throws Error naming the file and the field; write is atomic.
Rig readRig(const std::filesystem::path& path);
void writeRig(const Rig& rig, const std::filesystem::path& path);

}  // namespace previz
