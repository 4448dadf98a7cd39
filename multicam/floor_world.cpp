#include "multicam/floor_world.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/rig_world.h"
#include "multicam/detail/bundle.h"
#include "multicam/detail/views.h"

namespace previz::multicam {

namespace {

// Below this spread of the cameras seeing the board (RMS distance from their mean, against their
// mean distance to the board) the scale rests on the PnP depths' differences alone: not fixed.
constexpr double kMinSpreadOfDistance = 0.01;

void refuseFlip(const ImportOptions& options) {
  if (options.flip != "none")
    throw Error("--world floor fixes the world's axes itself; leave out --flip (got '" + options.flip + "')",
                fieldContext("flip"));
}

struct FloorView {
  int camera = -1;
  Pose T_cam_board;  // metres, the view's PnP
};

// The scale in closed form from the views' PnP: view v puts the board's origin at
// X = s C_v + R_v t_v (C_v, R_v: its camera's centre in rig units and rotation; t_v: the board's
// origin in the camera, metres). Least squares over X and s, with d_v = R_v t_v:
// s = -sum (C_v - mean C) . (d_v - mean d) / sum |C_v - mean C|^2. Throws Error naming the field
// 'fit_scale' when the cameras cannot fix it and it is required, else returns 0.
double closedFormScale(const Rig& rig, const std::vector<FloorView>& views, bool required) {
  const auto refuse = [&](const std::string& why) -> double {
    if (required) throw Error("place on floor: the rig's scale is not fixed: " + why, fieldContext("fit_scale"));
    return 0.0;
  };
  const int n = static_cast<int>(views.size());
  Eigen::Vector3d mean_c = Eigen::Vector3d::Zero(), mean_d = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> c(n), d(n);
  double distance_m = 0;
  std::vector<int> cameras;
  for (int v = 0; v < n; ++v) {
    const Pose& T_rig_cam = rig.cameras[views[v].camera].T_world_cam;
    c[v] = T_rig_cam.translation();
    d[v] = T_rig_cam.linear() * views[v].T_cam_board.translation();
    mean_c += c[v] / n;
    mean_d += d[v] / n;
    distance_m += views[v].T_cam_board.translation().norm() / n;
    if (std::find(cameras.begin(), cameras.end(), views[v].camera) == cameras.end())
      cameras.push_back(views[v].camera);
  }
  if (cameras.size() < 2)
    return refuse("it needs 2 or more cameras seeing the floor board (" + std::to_string(cameras.size()) + " do)");
  double num = 0, den = 0;
  for (int v = 0; v < n; ++v) {
    num -= (c[v] - mean_c).dot(d[v] - mean_d);
    den += (c[v] - mean_c).squaredNorm();
  }
  const double s = den > 0 ? num / den : 0.0;
  char why[256];
  if (den > 0 && !(s > 0 && std::isfinite(s))) {
    std::snprintf(why, sizeof(why), "the cameras' positions and their views of the board disagree (closed-form "
                                    "scale %.3g): are the poses inverted?", s);
    return refuse(why);
  }
  const double spread_m = s * std::sqrt(den / n);
  if (!(spread_m >= kMinSpreadOfDistance * distance_m)) {
    std::snprintf(why, sizeof(why), "the %zu cameras seeing the floor board are at one place (%.3g m RMS apart, "
                                    "%.3g m from it): it needs them apart by 1 %% of that distance or more",
                  cameras.size(), spread_m, distance_m);
    return refuse(why);
  }
  return s;
}

}  // namespace

void FloorPlacementOptions::validate() const {
  if (min_points < 4)
    throw Error("place on floor: min_points must be >= 4 (got " + std::to_string(min_points) + ")",
                fieldContext("min_points"));
}

FloorPlacement placeRigOnFloor(const Rig& rig, const RigObservations& obs, const FloorPlacementOptions& options) {
  rig.validate();
  options.validate();
  if (!obs.has_floor || obs.floor.frames.empty())
    throw Error("place on floor: no floor frames (floor.json \"frames\")", fieldContext("floor"));
  const std::vector<std::map<int, detail::View>> views = detail::collectViews(obs, rig, options.min_points, 0);

  detail::BundleProblem problem;
  for (const RigCamera& rc : rig.cameras) {
    detail::BundleCamera bc;
    bc.camera = rc.camera;
    bc.T_world_cam = rc.T_world_cam;
    bc.pose_fixed = true;
    problem.cameras.push_back(bc);
  }
  std::vector<FloorView> posed;
  FloorPlacement out;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    FloorPlacementCamera pc;
    pc.camera = rig.cameras[c].camera.name;
    for (const auto& [frame, v] : views[c]) {
      if (!obs.isFloorFrame(frame) || !v.posed) continue;
      ++pc.views;
      posed.push_back({static_cast<int>(c), v.T_cam_board});
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
  if (posed.empty()) {
    throw Error("place on floor: no camera sees the floor board (>= " + std::to_string(options.min_points) +
                    " points) in the floor frames",
                fieldContext("floor"));
  }
  out.start_scale = closedFormScale(rig, posed, options.fit_scale);

  // The board's pose from the views' candidates (each camera's pose, its centre scaled, times its
  // PnP), then the bundle with the cameras held and the scale held or free.
  const auto solve = [&](double scale, bool free) {
    detail::BundleProblem p = problem;
    p.rig_scale = scale;
    p.rig_scale_free = free;
    std::vector<Pose> candidates;
    for (const FloorView& v : posed) {
      Pose T_rig_cam = rig.cameras[v.camera].T_world_cam;
      T_rig_cam.translation() *= scale;
      candidates.push_back(T_rig_cam * v.T_cam_board);
    }
    detail::BundleBoard board;
    board.T_world_board = detail::robustMeanPose(candidates).mean;
    p.boards.push_back(board);
    detail::BundleOptions bundle;
    bundle.min_points = options.min_points;
    detail::solveBundle(p, bundle);
    return p;
  };
  const auto scaleSigma = [](const detail::BundleProblem& p) {
    bool ok = false;
    double sigma = 0;
    detail::bundleCameraCovariances(p, detail::bundleSigmaPx(p), &ok, &sigma);
    return ok ? sigma : 0.0;
  };
  problem = solve(options.fit_scale ? out.start_scale : 1.0, options.fit_scale);
  if (options.fit_scale) {
    out.scale = out.implied_scale = problem.rig_scale;
    out.implied_scale_sigma = scaleSigma(problem);
  } else if (out.start_scale > 0) {
    const detail::BundleProblem free = solve(out.start_scale, true);
    out.implied_scale = free.rig_scale;
    out.implied_scale_sigma = scaleSigma(free);
  }

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
                                  const ImportOptions& options, const FloorPlacementOptions& floor_options) {
  refuseFlip(options);
  const std::filesystem::path floor_file = take / "floor.json";
  if (!std::filesystem::is_regular_file(floor_file))
    throw Error("place on floor: the take has no floor.json (which frames show the floor board)",
                fileContext(take.string(), "floor"));
  const FloorSpec floor = readFloor(floor_file);
  const std::vector<std::string> in_take = takeCameras(take);
  std::vector<std::string> cameras;
  for (const std::string& name : imported.rig.names())
    if (std::find(in_take.begin(), in_take.end(), name) != in_take.end()) cameras.push_back(name);
  if (cameras.empty())
    throw Error("place on floor: none of the imported cameras has images in the take (cams/<name>)",
                fileContext(take.string(), "cams"));
  DetectTakeOptions detect;  // only the span of the floor frames (readFloor refuses an empty list)
  detect.first_frame = *std::min_element(floor.frames.begin(), floor.frames.end());
  detect.last_frame = *std::max_element(floor.frames.begin(), floor.frames.end());
  const RigObservations obs = detectTake(take, cameras, floor.board, &floor, detect);
  return placeImportOnFloor(imported, obs, floor_file, options, floor_options);
}

FloorPlacement placeImportOnFloor(RigImport& imported, const RigObservations& obs,
                                  const std::filesystem::path& floor_file, const ImportOptions& options,
                                  const FloorPlacementOptions& floor_options) {
  refuseFlip(options);
  std::vector<std::string> absent;
  for (const std::string& name : imported.rig.names()) {
    const auto seen = [&](const CameraDetections& d) { return d.camera == name; };
    if (std::none_of(obs.cameras.begin(), obs.cameras.end(), seen)) absent.push_back(name);
  }
  const FloorPlacement p = placeRigOnFloor(imported.rig, obs, floor_options);

  const std::string take = floor_file.parent_path().string();
  placeImport(imported, p.T_world_rig, p.scale,
              Rig{}.world_frame + " (the floor board of " + floor_file.string() + ")",
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
  // The scale with its sigma (the bundle's) and where the bundle started (the views' PnP).
  char scale[160];
  std::snprintf(scale, sizeof(scale), "%.6g +- %.2g (1 sigma; closed form from the cameras' views %.6g)",
                p.implied_scale, p.implied_scale_sigma, p.start_scale);
  if (floor_options.fit_scale) {
    r.assumptions.push_back("world: the imported relative poses trusted; the rig moved as a whole and its positions "
                            "scaled by " + std::string(scale) + " after --units " + options.units +
                            ", fitted with the board pose (--fit-scale)");
  } else {
    r.assumptions.push_back("world: the imported poses and their scale (--units " + options.units +
                            ") trusted; only the rig as a whole moved" +
                            (p.implied_scale > 0 ? "; the board implies a scale of " + std::string(scale)
                                                 : std::string("; the scale not checked (the cameras seeing the "
                                                               "board cannot fix it)")));
    if (p.implied_scale > 0) {
      const std::string warning =
          impliedScaleWarning(p.implied_scale, p.implied_scale_sigma, "the floor board implies", options);
      if (!warning.empty()) r.warnings.push_back(warning);
    }
  }
  for (const std::string& name : absent)
    r.warnings.push_back("world: camera '" + name + "' has no images in " + take + "; moved with the rig");
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
