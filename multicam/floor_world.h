#pragma once
// A rig whose cameras are already calibrated (intrinsics and extrinsics, e.g. imported from
// another tool) placed in the world frame the floor board defines, the same world calibrateRig
// sets (multicam/rig_calib.h; FloorSpec::T_world_board, z up, metres): the board's pose in the
// rig's frame from every camera that sees it, cameras held, then T_world_rig. The rig is not
// re-calibrated: its relative poses are trusted, and the residuals say how well they agree with
// the board. Its scale is trusted too, and only checked, unless fit_scale: a rig in arbitrary
// units (COLMAP, another reconstruction) takes its metric scale from the board's squares.
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

struct FloorPlacementOptions {
  // Solve the scale of the rig's positions with the board pose: needs 2 or more cameras seeing
  // the board from places apart by at least 1 % of their distance to it.
  bool fit_scale = false;
  int min_points = 6;  // board points a camera view needs
  void validate() const;  // throws Error naming the field
};

struct FloorPlacement {
  // previz's world <- the rig's frame, its positions first multiplied by `scale` (as
  // core/rig_world.h placeRig applies them).
  Pose T_world_rig = Pose::Identity();
  Pose T_rig_board = Pose::Identity();   // the floor board in the rig's frame, scaled
  double scale = 1.0;                    // 1 unless fit_scale
  // The scale the board implies (the bundle with it free) and its standard deviation (normal
  // equations, the residuals' noise); with fit_scale it is `scale`. 0 when the cameras seeing the
  // board cannot fix it (fit_scale off: one camera, or all at one place). start_scale: the
  // closed-form estimate the bundle started from.
  double implied_scale = 0, implied_scale_sigma = 0, start_scale = 0;
  std::vector<FloorPlacementCamera> cameras;  // rig order; views = 0: does not see the board
  int points = 0, rejected = 0;
  double rms_px = 0;                     // over the points kept
};

// obs: the floor frames of a take (obs.has_floor; other frames are ignored). Every floor frame
// shows the same still board, so all of them are one board pose: the robust mean of one
// candidate per camera view (the camera's pose times its PnP), refined by a bundle with every
// camera held (robust loss, outlier rounds). The scale starts from the views' PnP in closed form
// (each puts the board's origin at s C + R t: least squares over s and the origin) and is
// refined in that bundle, the cameras' centres multiplied by it. Throws Error naming the field
// 'floor' when obs has no floor frames or no camera sees the floor board in them, and
// 'fit_scale' when the cameras seeing it cannot fix the scale.
FloorPlacement placeRigOnFloor(const Rig& rig, const RigObservations& obs, const FloorPlacementOptions& options = {});

// `camera import --world floor:TAKE`: the floor board detected in TAKE's floor frames
// (TAKE/floor.json, its board inline or by path) by every camera of the import that has images
// in the take (cams/<name>/), the rig placed on it, and the report told what was assumed and how
// well the cameras agree. A camera of the import without images in the take, or not seeing the
// board, is a warning (it still moves with the rig). Refuses options.flip other than "none": the
// board fixes the axes. Throws Error naming the take folder when it has no floor.json or none of
// the import's cameras. The report gives the scale fitted (with its sigma and closed-form start),
// or warns when the one the board implies is > 1 % from 1 (a wrong --units, a rig without scale).
FloorPlacement placeImportOnFloor(RigImport& imported, const std::filesystem::path& take,
                                  const ImportOptions& options, const FloorPlacementOptions& floor = {});
// The same on the floor frames' detections already made (obs, floor_file: the take's floor.json
// they come from); an imported camera absent from obs has no images in the take.
FloorPlacement placeImportOnFloor(RigImport& imported, const RigObservations& obs,
                                  const std::filesystem::path& floor_file, const ImportOptions& options,
                                  const FloorPlacementOptions& floor = {});

}  // namespace previz::multicam
