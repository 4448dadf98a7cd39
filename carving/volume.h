#pragma once
// The volume to carve found from the cameras and one frame's silhouettes, in any units: for a
// rig whose cameras look inward at a common object (a turntable, a capture volume, a stage), of
// which nothing is known beforehand (another tool's calibration, object size unknown).
#include <vector>

#include <Eigen/Geometry>

#include "carving/hull.h"
#include "core/rig.h"

namespace previz::carving {

struct FoundVolume {
  Eigen::AlignedBox3d box;        // the hull's bounding box, grown by three coarse cells
  Eigen::Vector3d look_at;        // the point nearest every optical axis
  double radius = 0;              // median distance of the cameras from it
  long long coarse_cells = 0;     // cells of the coarse hull the box holds
};

// 1. The point nearest to every camera's optical axis (least squares) and the median camera
//    distance r from it: the cube of half-edge r there holds what the cameras look at.
// 2. That cube carved at 64 cells an edge with the silhouettes (k of 'options'; cells seen by
//    at least half the cameras); the bounding box of the surviving cells, grown by one cell.
// Throws Error (field "volume") when the optical axes are (nearly) parallel or the silhouettes'
// cones do not meet.
FoundVolume volumeFromSilhouettes(const std::vector<RigCamera>& cameras, const Silhouettes& silhouettes,
                                  const HullOptions& options);

}  // namespace previz::carving
