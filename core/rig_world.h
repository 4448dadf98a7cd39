#pragma once
// An imported rig placed in previz's world (z up, floor at z = 0, metres; docs/conventions.md):
// a rigid motion T_world_rig (optionally with a scale) applied to every camera, from points
// whose coordinates are known both in the world and in the imported file's frame (`camera
// import --world points:FILE`), or from a floor board the rig's cameras see (the multicam module
// finds its pose; `camera import --world floor:TAKE`). Every placement adds to the import
// report what it assumed and how well the points agree.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"
#include "core/rig_import.h"

namespace previz {

// points.json: {"points": [{"name": "A", "world": [x, y, z], "rig": [x, y, z]}, ...],
//               "fit_scale": false}
// "world" in metres in previz's world; "rig" in the imported file's frame and unit (the unit
// `--units` names: the same scale is applied to them as to the file's translations).
// "fit_scale": true also fits a scale (a rig from COLMAP or another reconstruction without a
// metric scale); by default the motion is rigid and the scale the points imply is only checked.
struct WorldPoint {
  std::string name;
  Eigen::Vector3d world_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d rig = Eigen::Vector3d::Zero();
};
struct WorldPoints {
  std::vector<WorldPoint> points;
  bool fit_scale = false;
  std::string file;  // for errors and the report
};
// Throws Error naming the file and the field (point index or name) for a missing or non-finite
// coordinate, a repeated name, fewer than 3 points.
WorldPoints readWorldPoints(const std::filesystem::path& file);

struct WorldPlacement {
  Pose T_world_rig = Pose::Identity();  // world <- imported rig (metres)
  double scale = 1.0;                   // applied to the rig before T_world_rig (1 unless fit_scale)
  double implied_scale = 1.0;           // the least-squares similarity's scale: ~1 when --units is right
  double rms_m = 0, max_m = 0;          // point residuals after the placement, metres
  std::string worst;                    // the point with max_m
};

// Least squares (Umeyama 1991) over the points, the rig's coordinates scaled to metres by
// metres_per_unit. Throws Error naming the file and field "points" when they are fewer than 3 or
// (nearly) collinear: a rotation about their line would fit as well.
WorldPlacement fitWorldPlacement(const WorldPoints& points, double metres_per_unit);

// Moves every camera: T_world_cam' = T_world_rig * S(scale) * T_world_cam (the scale on the
// positions only), and names the new world frame.
void placeRig(Rig& rig, const Pose& T_world_rig, double scale, const std::string& world_frame);
// The same on an import, whose report then says that the axes came from 'by' (the import's
// "axes: the file's world taken as z up" no longer holds).
void placeImport(RigImport& imported, const Pose& T_world_rig, double scale, const std::string& world_frame,
                 const std::string& by);

// The warning of a placement that kept the file's scale when its reference implies one more
// than 1 % from 1 (a wrong --units, a rig without metric scale); empty within 1 %. who_implies:
// "the points imply", "the floor board implies"; sigma > 0 is printed with the scale.
std::string impliedScaleWarning(double implied_scale, double sigma, const std::string& who_implies,
                                const ImportOptions& options);

// --world points:FILE on an import: fits, places the rig, and writes into the report what was
// assumed (the points' frames and units, rigid or with a scale) and how the points agree;
// warns when a point is off by more than 1 cm or the implied scale is off 1 by more than 1 %
// (a wrong --units, a point measured in the wrong place). Refuses options.flip other than
// "none": the points fix the axes, a flip would be silently overridden.
WorldPlacement placeImportByPoints(RigImport& imported, const WorldPoints& points, const ImportOptions& options);

}  // namespace previz
