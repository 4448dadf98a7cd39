#pragma once
// Frame-sync check of a rig take from the board's motion alone: for every pair of cameras that
// see the moving board together, the relative pose T_a_board(t) * T_b_board(t + d)^-1 is constant
// over t only at the right offset d. Pair offsets are combined into one offset per camera
// (the majority of cameras defines offset 0). Needs intrinsics only (poses not used).
//
// Board poses: PnP (IPPE, with the camera's distortion) per camera per moving (non-floor) frame.
// Score of a pair at offset d: over the frames t both see, the relative pose
// T_a_b(t) = T_a_board(t) * T_b_board(t + d)^-1; spread = median distance of its translation (b's
// centre in a's frame) from their component-wise median + |that median| x the median angle of
// its rotation from their robust mean (radians x baseline = metres). Per camera offsets: every
// decisive pair votes offset(b) - offset(a) = best d; per connected component of the votes,
// offsets are spread from each camera in turn along the votes and the assignment most votes
// agree with is kept; then the component's most common offset is subtracted (ties: the offset
// nearest 0). A component of two cameras that disagree cannot say which one is off: the camera
// listed later gets the offset.
#include <string>
#include <vector>

#include "core/rig.h"
#include "multicam/observations.h"

namespace previz::multicam {

struct SyncOptions {
  int max_offset = 5;        // frames searched each way
  int min_shared_frames = 6; // pairs with fewer co-visible moving frames are not used
  int min_points = 8;        // board views with fewer points give no pose
  // A pair votes only when its best offset is clearly better than the others: score(best) <
  // decisive_ratio x the median score over all offsets (a board held still fits every offset).
  double decisive_ratio = 0.5;
  // ... and its spread is below this fraction of the distance between the two cameras (right
  // offsets: ~0.2 % on the studio rig; wrong ones: tens of %).
  double max_relative_spread = 0.05;
  int threads = 0;           // OpenMP threads (0 = default)
  void validate() const;     // throws Error naming the field
};

// One camera pair: a's frame t is matched with b's frame t + offset.
struct PairSync {
  std::string a, b;
  int best_offset = 0;       // = offset(b) - offset(a) when both are sound
  int shared_frames = 0;     // at best_offset
  double spread_at_best = 0, spread_at_zero = 0;  // m (-1 where too few shared frames)
  bool decisive = false;     // voted
};

struct CameraSync {
  std::string camera;
  int offset_frames = 0;     // camera's frame f shows what the reference cameras show at f - offset
  double spread_at_offset = 0;   // pose-consistency score at the chosen offset (m, lower = better;
                                 // -1 when the camera could not be checked)
  double spread_at_zero = 0;     // ... at offset 0
  int pairs = 0;                 // camera pairs that voted
  bool in_sync = true;
};

struct SyncReport {
  std::vector<CameraSync> cameras;   // order of rig.cameras
  bool ok = true;                    // every camera in sync
  std::vector<std::string> unchecked;  // cameras that shared too few moving frames to check
  std::vector<PairSync> pairs;         // every pair with enough shared frames
  int max_offset = 0;                  // searched range
};

SyncReport checkSync(const RigObservations& obs, const Rig& intrinsics,
                     const SyncOptions& options = {});

}  // namespace previz::multicam
