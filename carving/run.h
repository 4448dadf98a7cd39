#pragma once
// The per-frame carving job behind `previz carve`: key every camera (or take its mask), carve
// the hull, write the main view's depth (EXR + preview PNG), the hull mesh (PLY + OBJ), the
// surface point cloud (PLY + PCD) and, last, the frame's report line. Resumable: a frame whose
// report exists for the same settings, with every output beside it, is skipped. Every file is
// written atomically. A frame's outputs depend on that frame (and the take's reference frames)
// only, not on what the process carved before: a resumed or sharded run writes the bytes an
// uninterrupted one does (scripts/killtest.sh). Output layout: docs/formats.md ("Carve output").
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "carving/hull.h"
#include "carving/keyer.h"
#include "carving/pointcloud.h"
#include "carving/refine.h"
#include "carving/take.h"

namespace previz::carving {

// Frames [first, end) of the take; end < 0 = to the last frame.
struct FrameRange {
  int first = 0;
  int end = -1;
  bool contains(int frame) const { return frame >= first && (end < 0 || frame < end); }
};
// "A:B" (A inclusive, B exclusive), "A:" (from A), ":B", or "A" (just frame A). Throws Error
// naming the flag (--frames) otherwise.
FrameRange parseFrameRange(const std::string& text);

// Shard i of n: the i-th of every n selected frames (round robin, so shards balance).
struct Shard {
  int index = 0;
  int count = 1;
};
Shard parseShard(const std::string& text);  // "i/n" with 0 <= i < n; throws naming --shard

struct RunOptions {
  std::filesystem::path out;       // output folder (created)
  HullOptions hull;                // volume, voxel_m, k, threads
  KeyerOptions keyer;
  PointCloudOptions points;
  // points/: the hull's surface point cloud (PLY + PCD). false: none is written, and PCL (in
  // its plugin, pointcloud.h) is not loaded.
  bool write_points = true;
  FrameRange frames;
  Shard shard;
  // Camera the depth map is made for: "" = the rig's camera with role "main"; when the rig has
  // none, no depth is written.
  std::string depth_camera;
  // More cameras to write hull depth for, each in depth_cameras/<cam>/ (inside its own key or
  // mask, at its pose for the frame): e.g. every witness, for post. The depth camera itself and
  // repeats are left out. Only the depth camera gets depth_refined/.
  std::vector<std::string> extra_depth_cameras;
  // Volume from the take's first selected frame (carving/volume.h): the carving cameras' look-at
  // point and their silhouettes, in the rig's own units (hull.volume is then ignored); with
  // voxel_cells > 0 the finest cell is the found box's longest edge / voxel_cells (hull.voxel_m
  // ignored). Every shard and every resumed run finds the same box from the same frame.
  bool volume_from_silhouettes = false;
  int voxel_cells = 0;
  // Cameras that carve: empty = every camera with role "witness".
  std::vector<std::string> carve_cameras;
  // The carving cameras' keys: a pixel is inside where its alpha is at or above this (the
  // keyer's silhouette_threshold, for them only; the depth cameras keep keyer's). A hull is the
  // intersection of every view's silhouette, so each view's edge error at 0.5 (a pixel half
  // covered, placed by noise and calibration to a fraction of a pixel) erodes it once more; below
  // 0.5 the partly covered edge pixels stay in and the hull stays around the object (the Oxford
  // dino's 35 views: 98.0 % of a left-out view covered at 0.5, 99.2 % at 0.25, the IoU unchanged).
  double carve_threshold = 0.5;
  // true: depth only inside the depth camera's silhouette (its key or mask); false: wherever
  // the pixel's ray meets the hull (e.g. a camera left out of the carve, to check the hull).
  bool depth_inside_silhouette = true;
  // Also write depth_refined/: the depth camera's depth beyond the visual hull by
  // photo-consistency of the plates (refine.h), beside the hull depth. Needs the plates
  // (cams/<cam>/%06d.png) of the depth camera and the carving cameras, also with masks; gains
  // from take.json "camera_gains".
  bool refine_depth = false;
  RefineOptions refine;
  // With refine_depth: the photo hull (refine.h photoHullDepth: every carving camera's depth
  // refined too, their free space carving the depth camera's); its own 'refine' field is
  // replaced by 'refine' above. rounds = 0: refineDepth alone (about 5x faster, measured
  // 0.1-0.4 points fewer pixels ordered at 10 cm).
  PhotoHullOptions photo_hull;
  void validate() const;  // throws Error naming the field
};

struct DroppedCamera {
  std::string camera;
  std::string reason;
};

// What one frame did; written as one JSON line (report/%06d.json) after every other output.
// Hull depth written for one camera in one frame.
struct DepthReport {
  std::string camera;
  std::string silhouette;          // "key" | "mask" | "none: <why>"
  long long pixels = 0;            // finite depth pixels
  double min_m = 0, max_m = 0;     // range of the preview's colour scale
  nlohmann::json toJson() const;
};

struct FrameReport {
  int frame = 0;
  std::vector<std::string> cameras_used;
  std::vector<DroppedCamera> cameras_dropped;  // carve cameras and the depth camera
  std::string depth_camera;                    // "" = no depth output
  std::string depth_silhouette;                // "key" | "mask" | "none: <why>"
  long long surface_cells = 0, inside_cells = 0, cells_tested = 0;
  double volume_m3 = 0;            // inside cells + half the surface cells
  long long depth_pixels = 0;      // finite depth pixels
  double depth_min_m = 0, depth_max_m = 0;  // range of the preview's colour scale
  std::vector<DepthReport> extra_depths;     // extra_depth_cameras, in their order
  // With refine_depth: "plates" (refined) or "none: <why>" (depth_refined = the hull depth), the
  // pixels refined and given a deeper depth, and its time (part of depth_ms).
  std::string refine_source;
  std::string refine_method;  // "photo hull" or "photo-consistency" (photo_hull.rounds = 0)
  long long refine_pixels = 0, refine_moved = 0;
  long long refine_free_space = 0;  // pixels whose hull entry the witnesses see through
  std::vector<std::string> refine_witnesses;
  std::vector<std::string> refine_gains_estimated;  // witnesses whose gain take.json lacks
  double refine_ms = 0;
  long long mesh_vertices = 0, mesh_faces = 0, points = 0;
  // key: read + key (or read masks); mesh: Carver::mesh; export: point cloud + every write of
  // the geometry; depth includes its EXR and preview writes.
  double key_ms = 0, carve_ms = 0, depth_ms = 0, mesh_ms = 0, export_ms = 0, total_ms = 0;
  nlohmann::json toJson() const;  // plus "config" added by the job
};

struct FailedFrame {
  int frame = 0;
  std::string reason;
};

struct RunSummary {
  std::vector<int> selected;        // frames of this shard and range
  std::vector<int> skipped;         // already finished (resumed)
  std::vector<FrameReport> carved;  // carved in this run
  std::vector<FailedFrame> failed;  // not finished: no report written, redone next run
  double ms = 0;
};

class CarveJob {
 public:
  // Builds the Carver for the carving cameras and one Keyer per camera (with its clean plate).
  // Throws Error naming the option, camera or file. 'take' must outlive the job.
  CarveJob(const Take& take, const RunOptions& options);
  ~CarveJob();
  CarveJob(const CarveJob&) = delete;
  CarveJob& operator=(const CarveJob&) = delete;

  const RunOptions& options() const;
  const std::vector<std::string>& carveCameras() const;
  const std::string& depthCamera() const;
  const std::vector<std::string>& extraDepthCameras() const;

  // Frames of the take in the range and this shard, ascending.
  std::vector<int> selectedFrames() const;

  // Output paths of one frame; the report is last in the list.
  std::vector<std::filesystem::path> outputs(int frame) const;
  std::filesystem::path reportPath(int frame) const;
  // True when the report exists for the same settings and every other output is beside it.
  bool finished(int frame) const;

  // Carves one frame and writes its outputs (report last). Throws Error naming the frame when
  // the frame cannot be carved; a missing or bad camera frame only drops that camera.
  FrameReport runFrame(int frame);

  // Every selected frame that is not finished, one at a time; a frame that fails is recorded
  // and the job goes on. progress(done, total) after each frame. At the end carve.jsonl (every
  // finished frame's report line, in frame order) is rewritten.
  RunSummary run(const std::function<void(int done, int total)>& progress = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::carving
