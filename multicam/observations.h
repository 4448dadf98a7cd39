#pragma once
// What the rig solve reads: every camera's board detections in every frame of a rig take,
// plus which frames show the floor board that fixes the world frame.
// Pixels follow docs/conventions.md ((0,0) = centre of the top-left pixel).
#include <algorithm>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "calib/detect.h"
#include "calib/observations.h"
#include "core/board.h"
#include "core/pose.h"

namespace previz::multicam {

// The floor board: which frames show it lying on the floor and where its board frame sits in
// the world. Default pose: face up with the board origin at the world origin, board x = world x,
// board y = -world y, board z = -world z (a half turn about x), so the world is z up.
// floor.json: {"board": "board.json" | {...spec...}, "frames": [..], "T_world_board": {...}}
// ("board" as a path is relative to floor.json; "T_world_board" optional).
struct FloorSpec {
  BoardSpec board;
  std::vector<int> frames;
  Pose T_world_board = defaultFloorPose();

  // Half turn about x: world = board frame turned face up.
  static Pose defaultFloorPose() {
    Pose T = Pose::Identity();
    T.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
    return T;
  }
};
FloorSpec readFloor(const std::filesystem::path& path);  // throws Error naming file and field
void writeFloor(const FloorSpec& floor, const std::filesystem::path& path);  // board inline

// One camera's detections. Frames where the board was not found have no entry in 'frames';
// frames whose image could not be read (missing, corrupt, wrong size) are in 'failures' with
// the reason — reported, never fatal.
struct CameraDetections {
  std::string camera;
  cv::Size image_size;
  std::map<int, std::vector<calib::Observation>> frames;
  std::map<int, std::string> failures;
};

struct RigObservations {
  BoardSpec board;                   // the board waved through the volume
  int frame_count = 0;               // frames 0 .. frame_count - 1 of the take
  bool has_floor = false;            // floor.frames are floor-board frames (world frame)
  FloorSpec floor;
  std::vector<CameraDetections> cameras;

  bool isFloorFrame(int frame) const {
    return has_floor && std::find(floor.frames.begin(), floor.frames.end(), frame) != floor.frames.end();
  }
  const BoardSpec& boardOf(int frame) const { return isFloorFrame(frame) ? floor.board : board; }
  const CameraDetections* find(const std::string& camera) const {
    for (const CameraDetections& c : cameras) {
      if (c.camera == camera) return &c;
    }
    return nullptr;
  }
};

nlohmann::json observationsToJson(const RigObservations& obs);
RigObservations observationsFromJson(const nlohmann::json& j, const std::string& file = {});
void writeObservations(const RigObservations& obs, const std::filesystem::path& path);  // atomic
RigObservations readObservations(const std::filesystem::path& path);

struct DetectTakeOptions {
  calib::DetectOptions detect;
  int first_frame = 0;
  int last_frame = -1;   // inclusive; -1 = the take's last frame
  int threads = 0;       // 0 = OpenMP default
};
struct DetectProgress {
  int images_done = 0, images_total = 0;
  double elapsed_s = 0;
};

// Detects the board in cams/<camera>/%06d.png of a take folder for every camera named (frame
// count from take.json "frames", else from the files present). A camera folder that does not
// exist throws Error naming the camera and the folder; a missing or unreadable frame is
// recorded in that camera's failures. In floor frames the floor board is detected.
RigObservations detectTake(const std::filesystem::path& take,
                           const std::vector<std::string>& cameras, const BoardSpec& board,
                           const FloorSpec* floor, const DetectTakeOptions& options = {},
                           const std::function<void(const DetectProgress&)>& progress = {});

// Camera names of a take: take.json "cameras", else the folders under cams/.
std::vector<std::string> takeCameras(const std::filesystem::path& take);

}  // namespace previz::multicam
