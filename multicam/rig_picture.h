#pragma once
// The picture of a calibrated stage a technical director checks: top view and side view with
// every camera's frustum and name, the floor board, and a heat map of how many cameras see
// each floor cell at a given height.
#include <filesystem>
#include <optional>

#include "core/rig.h"
#include "multicam/observations.h"

namespace previz::multicam {

struct RigPictureOptions {
  double coverage_height_m = 1.0;   // height of the coverage slice
  double cell_m = 0.1;              // coverage cell size
  double half_extent_m = 0;         // drawn area +-extent around the origin (0 = fit the cameras)
  double frustum_m = 0.8;           // drawn frustum depth
  int width_px = 1600;
  void validate() const;            // throws Error naming the field
};

// Coverage: number of cameras whose image contains the point (x, y, height) in front of them,
// on a grid of cell_m over [-extent, extent]^2; row 0 = largest y (north up). CV_32S, n x n with
// n = ceil(2 extent / cell); cell (row r, col c) is centred at
// x = -extent + (c + 0.5) cell, y = extent - (r + 0.5) cell. Camera::project (distortion
// included) and Camera::inImage decide "contains".
cv::Mat coverageGrid(const Rig& rig, double half_extent_m, double cell_m, double height_m);

struct RigPicture {
  std::filesystem::path png, svg;
  cv::Size size;                 // of both (SVG in px units): width = options.width_px
  double half_extent_m = 0;      // drawn area actually used
  int max_coverage = 0;          // most cameras seeing one cell
};

// Writes <stem>.png and <stem>.svg (atomic): left the top view (x right, y up), right the side
// view (x right, z up) at the same scale, a title row, the coverage colour bar and a scale bar.
// floor: its board outline is drawn when given. Throws Error naming the field for bad options.
RigPicture writeRigPicture(const Rig& rig, const FloorSpec* floor, const std::filesystem::path& stem,
                           const RigPictureOptions& options = {});

}  // namespace previz::multicam
