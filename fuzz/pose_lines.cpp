// Pose lines (core/pose_lines.h readPoseLines): JSON lines {"frame", "T_world_cam": {"R", "t"},
// "state", "reason"} as truth/main_poses.jsonl and camera_poses.jsonl hold them.
#include <map>
#include <string>

#include "core/pose_lines.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("poses.jsonl");
    previz::fuzz::writeBytes(file.path(), data, size);
    std::map<int, std::string> unposed;
    previz::readPoseLines(file.path(), "T_world_cam", &unposed);
  });
}
