#pragma once
// The rig calibration of a take as `previz rig calibrate` runs it, as one library call (issue
// 34): board detections (multicam/observations.h detectTake, or a cache of them) -> the initial
// rig (known intrinsics, scaled to the take's image size where a lens table's differs, or a
// nominal pinhole for cameras the solve estimates) -> rig solve (multicam/rig_calib.h: spanning
// tree, bundle, world frame from the floor board or the reference camera) -> frame-sync check
// of every camera against the solved rig (multicam/sync.h). `previz rig calibrate` and
// `previz demo` both call calibrateRigTake; what each step decided is in the result's log.
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/board.h"
#include "core/names.h"
#include "core/rig.h"
#include "multicam/observations.h"
#include "multicam/rig_calib.h"
#include "multicam/sync.h"

namespace previz::multicam {

// What is calibrated: the take, its cameras, the boards, and what is known of each camera.
struct RigTake {
  std::filesystem::path take;
  std::vector<std::string> cameras;  // take order (takeCameras)
  BoardSpec board;
  std::optional<FloorSpec> floor;    // none: the world frame is the first camera's
  // Per camera, in `cameras` order: its intrinsics and role when known, nullopt when the solve
  // estimates them (RigCalibOptions::estimate_intrinsics must then name it) from a nominal guess.
  std::vector<std::optional<RigCamera>> known;
  std::string main_camera = kMainCamera;  // the role of an estimated camera of this name
};

struct RigPipelineOptions {
  DetectTakeOptions detect;
  // Board detections are read from this file when it holds the same take (cameras, boards,
  // files and their times, detector settings), else detected and written there. Empty: none.
  std::filesystem::path observations_cache;
  RigCalibOptions calib;
  SyncOptions sync;
  void validate() const;  // throws Error naming the field
};

struct RigPipelineResult {
  RigObservations observations;
  bool cached = false;    // the detections came from observations_cache
  double detect_s = 0;    // time spent detecting (0 when cached)
  Rig initial;            // where the solve started
  RigCalibResult calib;
  SyncReport sync;        // sync.ok false: a camera is out of sync (named in sync.cameras)
  std::vector<std::string> log;  // what each step decided, one line each
};

// The whole chain. Throws Error naming the camera when its intrinsics do not fit the take's
// images or the solve cannot place it; the sync check never throws for an out-of-sync camera,
// it reports it. progress: the detection's.
RigPipelineResult calibrateRigTake(const RigTake& take, const RigPipelineOptions& options = {},
                                   const std::function<void(const DetectProgress&)>& progress = {});

// The steps, for callers that run them apart (`rig check` and `rig resurvey` detect the same way).
// Board detections from options.observations_cache when it holds this take, else detected and
// written there.
struct TakeDetections {
  RigObservations observations;
  bool cached = false;
  double detect_s = 0;
  std::vector<std::string> log;
};
TakeDetections detectRigTake(const RigTake& take, const DetectTakeOptions& detect,
                             const std::filesystem::path& observations_cache = {},
                             const std::function<void(const DetectProgress&)>& progress = {});
// The initial rig (RigTake::known; a nominal pinhole, fx = fy = image width, for the rest, sized
// from the camera's detections). Lines for the log are appended to `log` when given.
Rig initialRig(const RigTake& take, const RigObservations& obs, std::vector<std::string>* log = nullptr);
// Solve, then the sync check (fills calib and sync of the result).
RigPipelineResult solveRigTake(const RigObservations& obs, const Rig& initial, const RigPipelineOptions& options = {});

}  // namespace previz::multicam
