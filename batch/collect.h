#pragma once
// `previz batch collect`: per take, the sequences post reads directly (docs/formats.md,
// "Batch: collected output"): actor.####.obj/.ply meshes (z up, and a y-up variant on request),
// actor.####.pcd point clouds, depth EXR sequences per camera, main-camera and prop animation as
// .chan (batch/chan.h) and JSON, a contact sheet PNG per take and one summary HTML page.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "batch/manifest.h"
#include "core/pose.h"

namespace previz::batch {

struct CollectOptions {
  std::filesystem::path out;
  bool y_up = false;         // also mesh_yup/actor.####.obj|.ply for Maya/Houdini
  int frame_offset = 0;      // collected frame number = take frame + offset
  bool partial = false;      // collect what is finished instead of refusing
  int contact_columns = 6;
  int thumb_width_px = 240;
  void validate() const;
};

struct CollectSummary {
  int frames = 0;                    // frames collected, all takes
  std::vector<std::string> missing;  // "take frame N (shard K: why)"
  nlohmann::json toJson() const;
  nlohmann::json takes = nlohmann::json::array();  // per take: folder, frames, files
};

// Throws Error naming the shard and frame when a frame is not finished (unless partial).
CollectSummary collectBatch(const Manifest& manifest, const CollectOptions& options);

// The take's main-camera pose per frame: from its main poses file where it has the frame, else
// the rig's pose; frames the file marks lost or bad (`previz track camera`) are left out.
// Throws Error naming the file and line.
std::vector<std::pair<int, Pose>> mainCameraPoses(const Manifest& manifest, const TakePlan& take);

// A sequence's file name: "actor.0012.obj" for ("actor", 12, "obj").
std::string sequenceName(const std::string& stem, int frame, const std::string& ext);

// Prop poses from track output JSON lines {"frame", "props": [{"id", "name", "T_world_prop":
// {"R", "t"}, "state"}]}: a take's work/<take>/track/poses.jsonl, or else its per-frame
// work/<take>/track/frames/%06d.json, written by a "track" stage. A prop without "name" is
// "prop<id>"; one without T_world_prop (not seen) is left out.
struct PropSample {
  int frame = 0;
  int id = 0;
  std::string name, state;
  Pose T_world_prop = Pose::Identity();
};
std::vector<PropSample> readPropTrack(const std::filesystem::path& path);

}  // namespace previz::batch
