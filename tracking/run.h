#pragma once
// `previz track` over a take folder: reads the cameras' frames through the take model
// (take/take.h) frame by frame, tracks every prop of props.json with PropTracker, writes one
// JSON line per frame (docs/formats.md, "Tracking")
// and optionally streams FreeD or OpenTrackIO over UDP as frames are done. `previz track camera`
// solves one camera's pose per frame from studio tags (props with T_world_prop).
// Inputs are never modified; outputs are written atomically.
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/names.h"
#include "core/pose_lines.h"
#include "core/rig.h"
#include "tracking/props.h"
#include "tracking/stream.h"
#include "tracking/tracker.h"

namespace previz::tracking {

struct TrackInput {
  std::filesystem::path take;        // a take folder (take/take.h)
  std::filesystem::path rig;         // rig.json
  std::filesystem::path props;       // props.json
  std::filesystem::path main_poses;  // optional JSON lines {"frame", "T_world_cam"} of a moving camera
  std::string moving_camera = kMainCamera;  // the camera main_poses moves
  std::vector<std::string> cameras;  // default: every rig camera
  std::filesystem::path truth;       // optional truth/props.jsonl: errors in the summary
};

struct TrackRunOptions {
  TrackerOptions tracker;
  std::filesystem::path out;         // poses.jsonl and track.json are written here
  int first_frame = 0, end_frame = -1;  // [first, end); end -1 = every frame found
  double fps = 0;                    // 0 = take.json's "fps", else 24
  // Shard i of n (`previz batch`): the i-th of every n frames selected by the range (round
  // robin, as `previz carve --shard`).
  int shard_index = 0, shard_count = 1;
  // Frame files (`--frame-files`, what a batch shard runs): every frame is tracked on its own
  // (the tracker starts over: full-frame search, no filter history, so a frame's poses depend on
  // nothing but its images — not on the sharding) and written as out/frames/%06d.json, its
  // poses.jsonl line, atomically; a frame whose file is already there and reads back is kept,
  // not tracked again (resume). poses.jsonl is not written (shards share out/).
  bool frame_files = false;
  std::string udp;                   // HOST:PORT; empty = no streaming
  StreamProtocol protocol = StreamProtocol::kFreeD;
  void validate() const;             // throws Error naming the field
};

struct PropRunSummary {
  int id = 0;
  std::string name;
  int tracked = 0, lost = 0;
  double median_sigma_position_mm = 0;
  // Against the truth (when given): errors of the filtered and of the measured poses.
  int truth_frames = 0;
  double median_position_error_mm = 0, max_position_error_mm = 0;
  double median_rotation_error_deg = 0, max_rotation_error_deg = 0;
  double median_measured_position_error_mm = 0, median_measured_rotation_error_deg = 0;
};

struct TrackRunSummary {
  int frames = 0;
  std::vector<PropRunSummary> props;
  int unknown_tags = 0;
  int full_frames = 0;
  int rescanned_frames = 0;          // frames whose predicted regions missed a tracked prop (tracker.h)
  std::vector<std::string> camera_failures;  // "camera 'x': frame 12: reason"
  std::vector<int> failed_frames;    // frames no camera had an image of: not tracked, not written
  double ms = 0, track_ms = 0;       // whole run / inside PropTracker::track
  int packets_sent = 0, packets_failed = 0;
  std::vector<std::string> cameras;
  std::filesystem::path poses;       // the JSON lines file (frame files: the frames/ folder)
  std::vector<int> selected;         // frames of the range and the shard
  int kept = 0;                      // frame files already there, not tracked again
};

// JSON lines {"frame", "props": [{"id", "T_world_prop"}]} (a synthetic take's truth/props.jsonl)
// -> frame -> prop id -> pose; throws Error naming the file and line.
std::map<int, std::map<int, Pose>> readPropTruth(const std::filesystem::path& path);

TrackRunSummary runTrack(const TrackInput& input, const TrackRunOptions& options,
                         const std::function<void(int done, int total)>& progress = {});

// `previz track camera`: the pose of one camera per frame from studio tags.
struct CameraTrackInput {
  std::filesystem::path take;
  std::filesystem::path rig;         // for the camera's intrinsics
  std::filesystem::path tags;        // props.json whose props have T_world_prop
  std::string camera = kMainCamera;
  std::filesystem::path truth;       // optional JSON lines {"frame", "T_world_cam"}
};
struct CameraTrackSummary {
  int frames = 0, solved = 0;
  std::vector<int> bad_frames;       // unreadable or not the rig camera's size: skipped, reported
  double median_sigma_position_mm = 0;
  int truth_frames = 0;
  double median_position_error_mm = 0, max_position_error_mm = 0;
  double median_rotation_error_deg = 0, max_rotation_error_deg = 0;
  double ms = 0;
  std::filesystem::path poses;       // out/camera_poses.jsonl: {"frame", "time_s", "T_world_cam", ...}
};
CameraTrackSummary runTrackCamera(const CameraTrackInput& input, const TrackRunOptions& options,
                                  const std::function<void(int done, int total)>& progress = {});

}  // namespace previz::tracking
