#include "multicam/floor_world.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/rig_world.h"
#include "multicam/detail/bundle.h"
#include "multicam/detail/views.h"

namespace previz::multicam {

FloorPlacement placeRigOnFloor(const Rig& rig, const RigObservations& obs, int min_points) {
  rig.validate();
  if (!obs.has_floor || obs.floor.frames.empty())
    throw Error("place on floor: no floor frames (floor.json \"frames\")", fieldContext("floor"));
  const std::vector<std::map<int, detail::View>> views = detail::collectViews(obs, rig, min_points, 0);

  detail::BundleProblem problem;
  for (const RigCamera& rc : rig.cameras) {
    detail::BundleCamera bc;
    bc.camera = rc.camera;
    bc.T_world_cam = rc.T_world_cam;
    bc.pose_fixed = true;
    problem.cameras.push_back(bc);
  }
  std::vector<Pose> candidates;
  FloorPlacement out;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    FloorPlacementCamera pc;
    pc.camera = rig.cameras[c].camera.name;
    for (const auto& [frame, v] : views[c]) {
      if (!obs.isFloorFrame(frame) || !v.posed) continue;
      ++pc.views;
      candidates.push_back(rig.cameras[c].T_world_cam * v.T_cam_board);
      for (size_t i = 0; i < v.ids.size(); ++i) {
        detail::BundlePoint p;
        p.camera = static_cast<int>(c);
        p.board = 0;
        p.p_board = v.p_board[i];
        p.px = v.px[i];
        problem.points.push_back(p);
      }
    }
    out.cameras.push_back(pc);
  }
  if (candidates.empty()) {
    throw Error("place on floor: no camera sees the floor board (>= " + std::to_string(min_points) +
                    " points) in the floor frames",
                fieldContext("floor"));
  }
  detail::BundleBoard board;
  board.T_world_board = detail::robustMeanPose(candidates).mean;
  problem.boards.push_back(board);
  detail::BundleOptions options;
  options.min_points = min_points;
  detail::solveBundle(problem, options);

  out.T_rig_board = problem.boards[0].T_world_board;
  out.T_world_rig = obs.floor.T_world_board * out.T_rig_board.inverse();
  std::vector<double> ssr(rig.cameras.size(), 0.0);
  double total = 0;
  for (const detail::BundlePoint& p : problem.points) {
    const double r2 = detail::bundleResidual(problem, p).squaredNorm();
    ssr[p.camera] += r2;
    ++out.cameras[p.camera].points;
    if (!p.active) {
      ++out.cameras[p.camera].rejected;
      ++out.rejected;
      continue;
    }
    total += r2;
    ++out.points;
  }
  for (size_t c = 0; c < out.cameras.size(); ++c) {
    FloorPlacementCamera& pc = out.cameras[c];
    pc.rms_px = pc.points > 0 ? std::sqrt(ssr[c] / pc.points) : 0.0;
  }
  out.rms_px = out.points > 0 ? std::sqrt(total / out.points) : 0.0;
  return out;
}

FloorPlacement placeImportOnFloor(RigImport& imported, const std::filesystem::path& take,
                                  const ImportOptions& options) {
  if (options.flip != "none")
    throw Error("--world floor fixes the world's axes itself; leave out --flip (got '" + options.flip + "')",
                fieldContext("flip"));
  const std::filesystem::path floor_file = take / "floor.json";
  if (!std::filesystem::is_regular_file(floor_file))
    throw Error("place on floor: the take has no floor.json (which frames show the floor board)",
                fileContext(take.string(), "floor"));
  const FloorSpec floor = readFloor(floor_file);
  const std::vector<std::string> in_take = takeCameras(take);
  std::vector<std::string> cameras, absent;
  for (const std::string& name : imported.rig.names())
    (std::find(in_take.begin(), in_take.end(), name) != in_take.end() ? cameras : absent).push_back(name);
  if (cameras.empty())
    throw Error("place on floor: none of the imported cameras has images in the take (cams/<name>)",
                fileContext(take.string(), "cams"));
  DetectTakeOptions detect;  // only the span of the floor frames (readFloor refuses an empty list)
  detect.first_frame = *std::min_element(floor.frames.begin(), floor.frames.end());
  detect.last_frame = *std::max_element(floor.frames.begin(), floor.frames.end());
  const RigObservations obs = detectTake(take, cameras, floor.board, &floor, detect);
  const FloorPlacement p = placeRigOnFloor(imported.rig, obs);

  placeImport(imported, p.T_world_rig, 1.0, Rig{}.world_frame + " (the floor board of " + floor_file.string() + ")",
              "the floor board of " + floor_file.string());
  ImportReport& r = imported.report;
  r.files.push_back(floor_file.string());
  char line[256];
  std::snprintf(line, sizeof(line), "%d points, RMS %.2f px, %d rejected", p.points, p.rms_px, p.rejected);
  std::string names;
  for (const FloorPlacementCamera& c : p.cameras)
    if (c.views > 0) names += (names.empty() ? "" : ", ") + c.camera;
  r.assumptions.push_back("world: the floor board of " + floor_file.string() +
                          " (world = the board frame as `rig calibrate` defines it, z up, floor at z = 0); its pose "
                          "from the imported cameras held (" + names + "): " + line);
  r.assumptions.push_back("world: the imported poses and their scale (--units " + options.units +
                          ") trusted; only the rig as a whole moved");
  for (const std::string& name : absent)
    r.warnings.push_back("world: camera '" + name + "' has no images in " + take.string() + "; moved with the rig");
  for (const FloorPlacementCamera& c : p.cameras) {
    if (c.views == 0 && std::find(absent.begin(), absent.end(), c.camera) == absent.end())
      r.warnings.push_back("world: camera '" + c.camera + "' does not see the floor board; moved with the rig");
    // Cameras that disagree with the board pose the others give it: a wrong pose in the file,
    // wrong units, or wrong intrinsics.
    if (c.points > 0 && c.rms_px > 2.0) {
      std::snprintf(line, sizeof(line), "world: camera '%s' is %.1f px RMS off the floor board the others see "
                                        "(its pose, the units or its intrinsics?)", c.camera.c_str(), c.rms_px);
      r.warnings.push_back(line);
    }
  }
  return p;
}

}  // namespace previz::multicam
