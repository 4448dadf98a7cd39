#pragma once
// Frame-sync check of a rig take from the board's motion alone: for every pair of cameras that
// see the moving board together, the relative pose T_a_board(t) * T_b_board(t + d)^-1 is constant
// over t only at the right offset d. Pair offsets are combined into one offset per camera
// (the majority of cameras defines offset 0). Needs intrinsics only (poses not used).
#include <string>
#include <vector>

#include "core/rig.h"
#include "multicam/observations.h"

namespace previz::multicam {

struct SyncOptions {
  int max_offset = 5;        // frames searched each way
  int min_shared_frames = 8; // pairs with fewer co-visible moving frames are not used
};

struct CameraSync {
  std::string camera;
  int offset_frames = 0;     // camera's frame f shows what the reference cameras show at f - offset
  double spread_at_offset = 0;   // pose-consistency score at the chosen offset (m, lower = better)
  double spread_at_zero = 0;     // ... at offset 0
  int pairs = 0;                 // camera pairs that voted
  bool in_sync = true;
};

struct SyncReport {
  std::vector<CameraSync> cameras;   // order of rig.cameras
  bool ok = true;                    // every camera in sync
  std::vector<std::string> unchecked;  // cameras that shared too few moving frames to check
};

SyncReport checkSync(const RigObservations& obs, const Rig& intrinsics,
                     const SyncOptions& options = {});

}  // namespace previz::multicam
