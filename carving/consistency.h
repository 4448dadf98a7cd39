#pragma once
// Does every camera agree with the others? For a camera c and a take frame t, the visual hull
// carved from the OTHER cameras (forgiving a few of them: k-of-n, so one bad camera does not
// spoil the judge of another) is projected into c and compared with c's own silhouette. A camera
// that is late, bumped, badly keyed or badly calibrated disagrees, each in its own way:
//   - late / early: its silhouette of frame t + d matches the hull of frame t better than its
//     own frame t does (the sync estimate searches d);
//   - bumped or mis-calibrated: the disagreement is one image shift, frame after frame;
//   - a keyer problem: its mask has holes inside its outline that the others' hull fills.
// Silhouettes come from the take's mattes when it has them, else from keying its plates (one
// Keyer per camera, frames in take order). Work is done at a reduced resolution (the cameras
// scaled with Camera::scaled), on sampled frames. Used by `previz take sync` and `take check`.
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "carving/keyer.h"
#include "carving/take.h"

namespace previz::carving {

struct ConsistencyOptions {
  double scale = 0.5;           // silhouettes and cameras at this fraction of their size
  double voxel_m = 0.02;        // hull cell of the judge
  int tolerance_k = 2;          // the hull from the others survives this many disagreeing cameras
  // Volume carved; empty (the default) = autoVolume() of the take's cameras.
  Eigen::AlignedBox3d volume;
  int search_frames = 8;        // sync: corrections -N .. N searched
  int sample_frames = 12;       // take frames judged (evenly spread, away from the ends)
  // Sync: the best correction must beat the runner-up by this much mean IoU, and the scores
  // must spread by min_spread (a take without motion scores every offset the same).
  double min_margin = 0.002;
  double min_spread = 0.01;
  // Check: a camera is flagged when the others' hull covers less of its silhouette than this
  // (median over frames), or less than the cameras' median by more than max_covered_drop. The
  // hull of the others is always a superset of the actor, so a camera in sync and in place has
  // its silhouette covered all but its edge pixels; how much of the hull falls outside its
  // silhouette depends on how many cameras carve, and is reported, not judged.
  double min_covered = 0.97;
  double max_covered_drop = 0.03;
  std::vector<std::string> cameras;  // cameras judged (and judging); empty = every rig camera
  KeyerOptions keyer;
  int threads = 0;
  void validate() const;        // throws Error naming the field
};

// The stage volume every carving camera sees: the intersection of the cameras' view frusta
// above the floor (z in [0, height_m]), as an axis-aligned box; cameras seeing none of it drop
// out of the intersection (then the box of what all but one see). Throws Error when no point
// is seen by two cameras.
Eigen::AlignedBox3d autoVolume(const std::vector<RigCamera>& cameras, double height_m = 2.5);

struct OffsetEstimate {
  std::string camera;
  int correction = 0;            // frames to add to the camera's offset (source = take + offset)
  long long offset = 0;          // the camera's offset with the correction
  double score = 0;              // mean IoU with the others' hull at the best correction
  double runner_up = 0;          // the best other correction's
  int runner_up_correction = 0;
  double spread = 0;             // best - worst
  bool confident = false;
  std::string evidence;          // for a person: why, or why not ("cannot tell: ...")
  std::vector<double> scores;    // per correction -N .. N
};

struct SyncEstimate {
  std::vector<OffsetEstimate> cameras;
  std::vector<int> frames;       // take frames judged
  nlohmann::json toJson() const;
};

// Estimates each camera's frame offset from the silhouettes (two passes: the second judges every
// camera against others already corrected by the first's confident corrections).
SyncEstimate estimateOffsets(const Take& take, const ConsistencyOptions& options,
                             const std::function<void(const std::string&)>& progress = {});

struct FrameCheck {
  int frame = 0;
  double iou = 0;                // own silhouette vs the others' hull
  double covered = 0;            // |S ∩ H| / |S|: how much of its silhouette the others' hull covers
  double outside = 0;            // |H \ S| / |H|: how much of that hull falls outside its silhouette
  std::string dropped;           // why the camera or the judge has nothing at this frame
};

struct CameraCheck {
  std::string camera;
  std::vector<FrameCheck> frames;
  double iou = 0, covered = 0, outside = 0;  // medians over the frames judged
  bool flagged = false;
  // The likely cause when flagged: "out of sync", "image shift", "keyer", "unknown" ("" = ok).
  std::string cause;
  std::string explanation;       // one line a person can act on
  int sync_correction = 0;       // out of sync: frames that fix it
  Eigen::Vector2d shift_px = Eigen::Vector2d::Zero();  // image shift: median, full-resolution px
  double hole_fraction = 0;      // keyer: share of its outline's area the others fill and it does not
};

struct TakeCheck {
  std::vector<CameraCheck> cameras;
  std::vector<int> frames;
  Eigen::AlignedBox3d volume;
  bool volume_automatic = false;
  nlohmann::json toJson() const;
};

TakeCheck checkTake(const Take& take, const ConsistencyOptions& options,
                    const std::function<void(const std::string&)>& progress = {});

}  // namespace previz::carving
