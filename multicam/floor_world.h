#pragma once
// A rig whose cameras are already calibrated (intrinsics and extrinsics, e.g. imported from
// another tool) placed in the world frame the floor board defines, the same world calibrateRig
// sets (multicam/rig_calib.h; FloorSpec::T_world_board, z up, metres): the board's pose in the
// rig's frame from every camera that sees it, cameras held, then T_world_rig. The rig is not
// re-calibrated: its relative poses and scale are trusted, and the residuals say how well they
// agree with the board.
#include <filesystem>
#include <string>
#include <vector>

#include "core/pose.h"
#include "core/rig.h"
#include "core/rig_import.h"
#include "multicam/observations.h"

namespace previz::multicam {

struct FloorPlacementCamera {
  std::string camera;
  int views = 0;        // floor frames in which it sees >= min_points of the board
  int points = 0;       // its board points in those views
  int rejected = 0;     // of those, outliers the refinement left out
  // Over all its points (rejected ones included) against the board pose the cameras share: a
  // camera whose pose disagrees with the others shows here even when its points were rejected.
  double rms_px = 0;
};

struct FloorPlacement {
  Pose T_world_rig = Pose::Identity();   // previz's world <- the rig's frame
  Pose T_rig_board = Pose::Identity();   // the floor board in the rig's frame
  std::vector<FloorPlacementCamera> cameras;  // rig order; views = 0: does not see the board
  int points = 0, rejected = 0;
  double rms_px = 0;                     // over the points kept
};

// obs: the floor frames of a take (obs.has_floor; other frames are ignored). Every floor frame
// shows the same still board, so all of them are one board pose: the robust mean of one
// candidate per camera view (the camera's pose times its PnP), refined by a bundle with every
// camera held (robust loss, outlier rounds). Throws Error naming the field 'floor' when obs has
// no floor frames or no camera sees the floor board in them.
FloorPlacement placeRigOnFloor(const Rig& rig, const RigObservations& obs, int min_points = 6);

// `camera import --world floor:TAKE`: the floor board detected in TAKE's floor frames
// (TAKE/floor.json, its board inline or by path) by every camera of the import that has images
// in the take (cams/<name>/), the rig placed on it, and the report told what was assumed and how
// well the cameras agree. A camera of the import without images in the take, or not seeing the
// board, is a warning (it still moves with the rig). Refuses options.flip other than "none": the
// board fixes the axes. Throws Error naming the take folder when it has no floor.json or none of
// the import's cameras.
FloorPlacement placeImportOnFloor(RigImport& imported, const std::filesystem::path& take,
                                  const ImportOptions& options);

}  // namespace previz::multicam
