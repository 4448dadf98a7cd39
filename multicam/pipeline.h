#pragma once
// The rig calibration of a take as `previz rig calibrate` runs it, as one library call (issue
// 34): board detections (multicam/detect_take.h, or a cache of them) -> rig solve from the
// cameras' intrinsics (multicam/rig_calib.h: spanning tree, bundle, world frame from the floor
// board or the reference camera) -> frame-sync check of every camera against the solved rig
// (multicam/sync.h). `previz rig calibrate` and `previz demo` both call it.
#include "core/rig.h"
#include "multicam/rig_calib.h"
#include "multicam/sync.h"

namespace previz::multicam {

struct RigPipelineOptions {
  RigCalibOptions calib;
  SyncOptions sync;
  void validate() const;  // throws Error naming the field
};

struct RigPipelineResult {
  RigCalibResult calib;
  SyncReport sync;  // sync.ok false: a camera is out of sync (named in sync.cameras)
};

// Throws (naming the camera) when the solve cannot place a camera; the sync check never throws
// for an out-of-sync camera, it reports it.
RigPipelineResult solveRigTake(const RigObservations& obs, const Rig& initial, const RigPipelineOptions& options = {});

}  // namespace previz::multicam
