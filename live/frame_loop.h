#pragma once
// The live previz frame: the library `previz run`, `previz bench run` and `previz demo` drive.
// How to run a frame:
//   FrameLoop loop(rig, cg_camera, options);           // once: keyers, carver, compositor
//   PropStage props(loop, rig, prop_set, {});           // optional: tagged props
//   props.addTo(loop);
//   TakeReader reader(take, loop, {});                  // inputs: live/inputs.h (or your own)
//   FrameState s;
//   reader.read(frame, s);                              // plates, main camera, CG frame
//   std::vector<StageTime> times = loop.run(s);         // s.composite, s.main_depth, s.hull, ...
// Per frame a list of stages, each timed, run in order on one FrameState:
//   key       every camera keyed (witnesses: silhouette; main: soft alpha + despill), in
//             parallel over cameras, one Keyer per camera kept across frames
//   carve     visual hull from the witness silhouettes (carving/hull.h)
//   depth     the hull's depth for the main camera at this frame's pose, inside its key
//   props     (optional, PropStage below) AprilTag-tagged props from the carving cameras' and
//             the main camera's plates (tracking/tracker.h), inserted after "depth"; its
//             cameras' tag searches run among the keys, in the key stage's pool of threads
//             (poolWithKey), and the stage solves and filters the poses
//   composite keyed main plate over the CG frame, depth-aware (composite/compositor.h)
// One frame is a function of (rig, camera frames, CG frame) plus the keyers' per-camera screen
// models (ARCHITECTURE.md) and, with the props stage, the prop tracker's filters and ROIs
// (PropStage): the loop holds no other state between frames. Reading inputs and
// writing outputs are the caller's (files, VideoCapture); they are timed by the caller.
// A stage can be inserted after any other (insertStage), e.g. prop tracking after "depth"; a
// stage reads and writes FrameState.
#include <functional>
#include <map>
#include <optional>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carving/hull.h"
#include "carving/keyer.h"
#include "composite/compositor.h"
#include "composite/output.h"
#include "core/rig.h"
#include "tracking/props.h"
#include "tracking/tracker.h"

namespace previz::live {

// The live loop carves at 2 cm, not the library's 5 mm, and its depth rays sample the
// silhouettes every 2.5 mm. Its only use of the hull is the main camera's depth: the carve only
// guides the rays (a carve keeps every cell some hull point may lie in), and each ray finds the
// exact hull of the silhouettes below the cell size whatever that is. Which thin hull slivers a
// ray can step over is set by its sampling step, not by the cell (the library's step is half a
// cell). t = 4 s, main at 960x540 (tests/carving/depth_test.cpp): p99 0.03 mm from the exact
// hull at 2 cm / 2.5 mm, 0.07 mm at 1 cm / 5 mm (the previous live setting), 0.02 mm at 5 mm.
// The 24 fps bench take (bench run, 2 threads, CPU ms, medians of 6 runs alternated with 1 cm /
// 5 mm): carve 28.8 -> 11.5, depth 20.9 -> 28.0, the frame 7 % less; depth against the exact
// hull 223 -> 154 pixels off, p95 0.030 -> 0.021 mm.
// Meshes for post come from previz carve at 5 mm, or previz run --meshes (1 cm unless --voxel).
constexpr double kLiveVoxelM = 0.02;
constexpr double kLiveDepthStepM = 0.0025;
constexpr double kLiveMeshVoxelM = 0.01;  // previz run --meshes without --voxel
inline carving::HullOptions liveHullOptions() {
  carving::HullOptions o;
  o.voxel_m = kLiveVoxelM;
  o.depth_step_m = kLiveDepthStepM;
  return o;
}

struct FrameLoopOptions {
  carving::HullOptions hull = liveHullOptions();
  carving::KeyerOptions keyer;              // for every camera (soft_alpha set per role)
  composite::CompositeOptions composite;
  std::string main_camera;                  // "" = the rig's camera with role "main"
  std::vector<std::string> carve_cameras;   // empty = every witness
  bool debug_layers = false;                // fill CompositeResult's layers
  // Witness plates are averaged over witness_bin x witness_bin pixels before keying, in light
  // taken as code^2 (a gamma-2 stand-in for sRGB, close enough for a mean and table-free), as a
  // sensor bins; the hull is carved against those smaller silhouettes through the witness
  // cameras scaled to match (Camera::scaled; the lens's distortion is the same in normalised
  // coordinates). 1 = full resolution. Live preview trades a little silhouette detail for time:
  // at 2 a witness keys a quarter of the pixels with half the sensor noise. The main camera is
  // always keyed and composited at full resolution, and props are tracked on the full plates.
  // The witness keyers' speck / hole sizes (KeyerOptions min_blob_px, min_hole_px, in full
  // pixels) are divided by witness_bin^2.
  int witness_bin = 1;
  // Witnesses keyed only around their last silhouette (KeyerOptions::region_margin_px): the
  // boxes of the last frame's silhouette parts grown by this many plate pixels (divided by
  // witness_bin), whole frames when something shows outside them, and one witness's whole frame
  // in turn every few frames. Carving needs their binary silhouettes only, which region keying
  // gives exactly (tests/carving/keyer_test.cpp). 0 = every frame keyed whole. Frames that are
  // not consecutive (FrameState::frame not one past the last) are keyed whole.
  int key_region_margin_px = 48;
  // The main camera keyed the same way (with the same margin; its whole frame every 24 frames
  // falls between the witnesses'). Its silhouette is the whole key's exactly, and so is its soft
  // alpha inside the regions; outside them the alpha is 0 where a whole key leaves a few stray
  // pixels of sensor noise at a small alpha, never silhouette (tests/carving/keyer_test.cpp: at
  // most 50 a frame). What it gives up: something new outside the regions that the probed rows
  // do not see (under 8 rows tall) is composited from the next whole frame, at most 24 frames
  // on. false = the main camera keyed whole on every frame.
  bool key_main_region = true;
  // Work a later stage pools with the key stage (FrameLoop::poolWithKey: the props stage's tag
  // searches) runs in the key stage's pool of threads, among the cameras' keys, so that neither
  // waits alone for its slowest camera. false = it runs as its own pool at the start of its stage
  // (the same results).
  bool pool_with_key = true;
  int threads = 0;                          // OpenMP threads (0 = default)
  void validate() const;                    // throws Error naming the field
};

// Everything one frame carries through the stages.
struct FrameState {
  int frame = 0;
  // Inputs (the caller fills them): one plate per carving camera (CV_8UC3; empty = the camera
  // is dropped for this frame, with its reason in 'dropped'), the main plate, the main camera at
  // this frame (pose, lens state) and the CG frame.
  std::vector<cv::Mat> witness_plates;
  std::vector<std::string> dropped;          // one per carving camera, "" = used
  cv::Mat main_plate;
  RigCamera main;
  composite::CgFrame cg;
  // Stage results.
  std::vector<cv::Mat> silhouettes;          // carving cameras (the loop's buffers, shared)
  // The main camera's key and despilled plate: the loop's buffers, shared like 'composite'.
  carving::KeyResult main_key;
  cv::Mat foreground;                        // despilled main plate
  carving::VisualHull hull;
  // CV_32FC1, +inf outside the hull / key: the loop's buffer, shared like 'composite'.
  cv::Mat main_depth;
  // The loop's composite buffers, shared: overwritten by the next run() (clone to keep).
  composite::CompositeResult composite;
  std::optional<tracking::TrackFrame> props;  // the props stage's frame (docs/formats.md, "Tracking")
};

struct StageTime {
  std::string stage;
  double ms = 0;      // wall time
  double cpu_ms = 0;  // CPU time of the process (every thread) during the stage: on a shared
                      // machine wall time also measures the other jobs
};

class FrameLoop {
 public:
  using StageFn = std::function<void(FrameState&)>;

  // cg: the engine's pinhole (cg/camera.json); main: the main camera's lens at the start (its
  // per-frame state comes with each FrameState; the CG distortion map is rebuilt when it
  // changes). Throws Error naming the camera or option.
  FrameLoop(const Rig& rig, const Camera& cg, const FrameLoopOptions& options);
  ~FrameLoop();
  FrameLoop(const FrameLoop&) = delete;
  FrameLoop& operator=(const FrameLoop&) = delete;

  const std::vector<std::string>& carveCameras() const;
  const std::string& mainCamera() const;
  std::vector<std::string> stages() const;
  const carving::Carver& carver() const;
  const composite::Compositor& compositor() const;
  // Adds a stage after the one named (throws Error naming 'after' when there is none).
  void insertStage(const std::string& after, const std::string& name, StageFn fn);
  // Per-camera work of the stage named 'stage' that does not need the keys (the props stage's
  // tag searches), run among the cameras' keys in the key stage's pool of threads, the items
  // longest first (each one's time estimated from the last frames: keys by camera, work by
  // pixel), so that the pool's threads finish together. plan(state) runs before the keys and
  // returns each item's pixels (0 = no item); item(i) runs on any thread, once for each planned
  // item, and must not throw (it records its failures for its stage). The key stage's wall and
  // CPU time are shared between "key" and 'stage' in proportion to the CPU time their items took.
  // With FrameLoopOptions::pool_with_key false, plan and the items run as a pool of their own at
  // the start of 'stage'. Throws Error naming 'stage' when there is no such stage.
  struct PooledWork {
    std::string stage;
    std::function<std::vector<long long>(FrameState&)> plan;
    std::function<void(int)> item;
  };
  void poolWithKey(PooledWork work);

  // Runs every stage on the state; returns each stage's wall time in order. Throws Error naming
  // the frame (and camera) when a stage fails; a dropped witness only leaves the carve.
  std::vector<StageTime> run(FrameState& state);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The "props" stage: one PropTracker for the whole run over the carving cameras and the main
// camera (in that order), fed each frame's plates (a dropped witness without a plate is reported
// "no image"); before each frame the main camera's pose is set from FrameState::main (the moving
// camera). Time is frame / fps. A frame earlier than the previous one, or more than the filter's
// max_gap_s after it, starts the tracker over (every track forgotten, full-frame search): the
// filter no longer bridges the gap, so its predicted ROIs would be guesses.
struct PropStageOptions {
  tracking::TrackerOptions tracker;
  double fps = 24;
  void validate() const;  // throws Error naming the field
};


class PropStage {
 public:
  // rig: the loop's rig (the main camera's lens as the loop uses it). Throws Error naming the
  // camera or the props' field.
  PropStage(const FrameLoop& loop, const Rig& rig, tracking::PropSet props, const PropStageOptions& options);
  ~PropStage();
  PropStage(const PropStage&) = delete;
  PropStage& operator=(const PropStage&) = delete;
  void operator()(FrameState& s);
  // Inserts this stage into the loop after "depth" as "props", its cameras' tag searches pooled
  // with the key stage (FrameLoop::poolWithKey); the stage must outlive the loop's runs.
  void addTo(FrameLoop& loop);
  const tracking::PropTracker& tracker() const { return *tracker_; }

 private:
  // Restarts the tracker when time ran back or jumped, sets the main camera's pose, gathers the
  // plates; returns the frame's time.
  double prepare(const FrameState& s);

  std::unique_ptr<tracking::PropTracker> tracker_;
  std::vector<cv::Mat> images_;  // the frame's plates: carving cameras', then the main camera's
  PropStageOptions options_;
  int main_index_ = 0;
  bool any_ = false;
  double last_time_s_ = 0;
};

}  // namespace previz::live
