// previz rig: calibrate every camera of a stage in one world frame from a rig take, check a
// calibrated rig (reprojection + frame sync) on a new capture, re-survey one bumped camera.
// Thin: resolve inputs, detect (multicam/observations.h), call multicam/, write outputs.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "calib/lens_table.h"
#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/rig.h"
#include "core/units.h"
#include "multicam/observations.h"
#include "multicam/rig_calib.h"
#include "multicam/rig_io.h"
#include "multicam/rig_picture.h"
#include "multicam/pipeline.h"
#include "multicam/sync.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;
using namespace previz::multicam;

constexpr int kExitCheckFailed = 3;
constexpr double kRadToDeg = degrees(1.0);

struct RigArgs {
  std::string take, board, floor, out, rig, camera, intrinsics, estimate, lens, main_camera = kMainCamera;
  std::string yaml_dir, picture, observations, compare, report;
  double focus = 0, zoom = 0;
  bool has_focus = false, has_zoom = false;
  bool no_floor = false, not_srgb = false, json = false, quiet = false;
  double flag_px = 1.0;
  int max_offset = 5;
  int threads = 0;
};

Error flagError(const std::string& flag, const std::string& message) {
  return Error(message, fieldContext(flag));
}

std::string fmt(const char* format, double value) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, value);
  return buf;
}

// ---------------------------------------------------------------------------------------------
// Inputs

BoardSpec boardOf(const RigArgs& a) {
  fs::path path = a.board;
  if (path.empty()) {
    path = fs::path(a.take) / "board.json";
    if (!fs::exists(path)) throw flagError("--board", "rig: give --board (no board.json in the take " + a.take + ")");
  }
  return readBoard(path);
}

// --floor, else <take>/floor.json when present, unless --no-floor.
std::optional<FloorSpec> floorOf(const RigArgs& a) {
  if (a.no_floor) return std::nullopt;
  if (!a.floor.empty()) return readFloor(a.floor);
  const fs::path in_take = fs::path(a.take) / "floor.json";
  if (fs::exists(in_take)) return readFloor(in_take);
  return std::nullopt;
}

void requireTake(const RigArgs& a) {
  if (!fs::is_directory(a.take)) {
    ErrorContext context;
    context.file = a.take;
    context.field = "--take";
    throw Error("rig: no such take folder", context);
  }
}

// How `previz rig` detects boards (the same for calibrate, check and resurvey).
DetectTakeOptions detectOptions(const RigArgs& a) {
  DetectTakeOptions options;
  options.detect.linear_light = !a.not_srgb;
  options.detect.measure_focus = false;
  options.threads = a.threads;
  return options;
}

// The board detections of the take (multicam/pipeline.h detectRigTake: the --observations cache
// when it holds this take, else detected with a progress line), and what was found.
RigObservations observe(const RigArgs& a, const std::vector<std::string>& cameras, const BoardSpec& board,
                        const std::optional<FloorSpec>& floor, double* detect_s, bool* cached) {
  RigTake take;
  take.take = a.take;
  take.cameras = cameras;
  take.board = board;
  take.floor = floor;
  std::unique_ptr<ProgressLine> progress;
  TakeDetections d = detectRigTake(take, detectOptions(a), a.observations, [&](const DetectProgress& p) {
    if (!progress) progress = std::make_unique<ProgressLine>("rig detect", p.images_total, a.quiet);
    progress->update(p.images_done);
  });
  for (const std::string& line : d.log) std::cerr << "rig: " << line << "\n";
  *detect_s = d.detect_s;
  *cached = d.cached;
  return std::move(d.observations);
}

nlohmann::json detectSummary(const RigObservations& obs, double detect_s, bool cached) {
  int views = 0, failures = 0;
  nlohmann::json cameras = nlohmann::json::array();
  for (const CameraDetections& c : obs.cameras) {
    views += static_cast<int>(c.frames.size());
    failures += static_cast<int>(c.failures.size());
    cameras.push_back({{"camera", c.camera}, {"views", c.frames.size()}, {"failures", c.failures.size()}});
  }
  const int images = obs.frame_count * static_cast<int>(obs.cameras.size());
  return {{"images", images}, {"views", views},     {"failures", failures}, {"seconds", detect_s},
          {"cached", cached}, {"cameras", cameras}, {"fps", detect_s > 0 ? images / detect_s : 0.0}};
}

void printDetections(const RigObservations& obs, double detect_s, bool cached) {
  int views = 0, failures = 0;
  for (const CameraDetections& c : obs.cameras) {
    views += static_cast<int>(c.frames.size());
    failures += static_cast<int>(c.failures.size());
  }
  const int images = obs.frame_count * static_cast<int>(obs.cameras.size());
  std::cerr << "rig detect: " << obs.cameras.size() << " cameras x " << obs.frame_count << " frames: board in "
            << views << " views";
  if (!cached && detect_s > 0) std::cerr << " (" << fmt("%.1f", detect_s) << " s, " << fmt("%.1f", images / detect_s) << " images/s)";
  std::cerr << "\n";
  if (failures > 0) {
    std::cerr << "rig detect: " << failures << " frames could not be read (not used):\n";
    int shown = 0;
    for (const CameraDetections& c : obs.cameras) {
      for (const auto& [frame, reason] : c.failures) {
        if (shown++ < 5) std::cerr << "  " << c.camera << " frame " << frame << ": " << reason << "\n";
      }
    }
    if (shown > 5) std::cerr << "  ... and " << shown - 5 << " more (see --observations)\n";
  }
}

// Intrinsics of every camera before the solve: from a rig.json or a folder of per-camera
// files (previz camera JSON <name>.json as `previz calib intrinsics` writes it, or OpenCV
// <name>.yaml), the main camera from a lens table, and a nominal guess for cameras whose
// intrinsics the solve estimates anyway. Cameras with none of these: an error naming them.
struct IntrinsicsSource {
  std::optional<Rig> rig;
  fs::path folder;
};

std::optional<RigCamera> intrinsicsFor(const RigArgs& a, const IntrinsicsSource& src, const std::string& name) {
  if (!a.lens.empty() && name == a.main_camera) {
    if (!a.has_focus || !a.has_zoom) throw flagError("--focus", "rig: --lens needs --focus and --zoom");
    const calib::LensTable table = calib::readLensTable(a.lens);
    const calib::LensTableEntry entry = table.at(a.focus, a.zoom);
    if (entry.clamped) {
      std::cerr << "rig: warning: focus " << a.focus << ", zoom " << a.zoom << " lies outside the lens table "
                << a.lens << "; clamped to its edge\n";
    }
    RigCamera rc;
    rc.camera = entry.camera;
    rc.camera.name = name;
    rc.role = kMainRole;
    return rc;
  }
  if (src.rig) {
    if (const RigCamera* rc = src.rig->find(name)) return *rc;
    return std::nullopt;
  }
  if (!src.folder.empty()) {
    const fs::path json = src.folder / (name + ".json");
    const fs::path yaml = src.folder / (name + ".yaml");
    RigCamera rc;
    if (fs::exists(json)) {
      rc.camera = cameraFromJson(readJsonFile(json), json.string());
    } else if (fs::exists(yaml)) {
      rc.camera = readOpenCvCamera(yaml, name);
    } else {
      return std::nullopt;
    }
    rc.camera.name = name;
    rc.role = name == a.main_camera ? kMainRole : "witness";
    return rc;
  }
  return std::nullopt;
}

bool estimated(const std::vector<std::string>& list, const std::string& name) {
  return std::find(list.begin(), list.end(), "*") != list.end() ||
         std::find(list.begin(), list.end(), name) != list.end();
}

// Resolved before detection so that a missing file fails in seconds, not after minutes.
std::vector<std::optional<RigCamera>> resolveIntrinsics(const RigArgs& a, const std::vector<std::string>& cameras,
                                                        const std::vector<std::string>& estimate) {
  IntrinsicsSource src;
  if (!a.intrinsics.empty()) {
    if (fs::is_directory(a.intrinsics)) src.folder = a.intrinsics;
    else if (fs::is_regular_file(a.intrinsics)) src.rig = readRig(a.intrinsics);
    else throw flagError("--intrinsics", "rig: --intrinsics " + a.intrinsics + " is neither a rig.json nor a folder");
  }
  if (!a.lens.empty() && std::find(cameras.begin(), cameras.end(), a.main_camera) == cameras.end()) {
    throw flagError("--main-camera", "rig: --lens is for the main camera '" + a.main_camera +
                                         "', which the take does not have (name it with --main-camera)");
  }
  std::vector<std::optional<RigCamera>> out;
  for (const std::string& name : cameras) {
    out.push_back(intrinsicsFor(a, src, name));
    if (!out.back() && !estimated(estimate, name)) {
      ErrorContext context;
      context.camera = name;
      context.field = "--intrinsics";
      std::string where = a.intrinsics.empty() ? std::string("no --intrinsics given")
                          : src.rig ? "not in " + a.intrinsics
                                    : "neither " + (src.folder / (name + ".json")).string() + " nor " +
                                          (src.folder / (name + ".yaml")).string() + " exists";
      throw Error("rig: no intrinsics for camera '" + name + "' (" + where +
                      "); calibrate it with `previz calib intrinsics`, or let the solve estimate it "
                      "with --estimate-intrinsics " + name,
                  context);
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Reports

// Differences to another rig (a previous calibration, or a synthetic take's truth), cameras of
// both; same world frame assumed (no alignment).
nlohmann::json compareRigs(const Rig& rig, const Rig& other) {
  nlohmann::json cameras = nlohmann::json::array();
  double max_pos = 0, max_rot = 0;
  for (const RigCamera& rc : rig.cameras) {
    const RigCamera* o = other.find(rc.camera.name);
    if (!o) continue;
    const double pos = translationDistance(rc.T_world_cam, o->T_world_cam);
    const double rot = rotationDistance(rc.T_world_cam, o->T_world_cam) * kRadToDeg;
    max_pos = std::max(max_pos, pos);
    max_rot = std::max(max_rot, rot);
    cameras.push_back({{"camera", rc.camera.name}, {"position_error_m", pos}, {"rotation_error_deg", rot}});
  }
  return {{"cameras", cameras}, {"max_position_error_m", max_pos}, {"max_rotation_error_deg", max_rot}};
}

void printCompare(const nlohmann::json& c, const std::string& other) {
  std::cerr << "rig: compared with " << other << ":";
  for (const auto& cam : c.at("cameras")) {
    std::cerr << " " << cam.at("camera").get<std::string>() << " "
              << fmt("%.1f mm", 1000 * cam.at("position_error_m").get<double>()) << "/"
              << fmt("%.3f deg", cam.at("rotation_error_deg").get<double>()) << ";";
  }
  std::cerr << " worst " << fmt("%.2f mm", 1000 * c.at("max_position_error_m").get<double>()) << ", "
            << fmt("%.3f deg", c.at("max_rotation_error_deg").get<double>()) << "\n";
}

void printCalib(const RigCalibResult& r) {
  std::cerr << "rig calibrate: " << r.rig.cameras.size() << " cameras, " << r.T_world_board.size()
            << " board frames, " << r.residuals << " residuals (" << r.rejected << " rejected), RMS "
            << fmt("%.3f", r.rms_px) << " px, world frame from "
            << (r.world_from_floor ? "the floor board" : "the reference camera") << ", "
            << fmt("%.0f", r.solve_ms) << " ms\n";
  std::fprintf(stderr, "  %-12s %-8s %6s %7s %8s %13s %14s   %s\n", "camera", "role", "views", "points", "rms px",
               "sigma pos mm", "sigma rot deg", "position m (world)");
  for (size_t i = 0; i < r.cameras.size(); ++i) {
    const CameraCalibReport& c = r.cameras[i];
    const RigCamera* rc = r.rig.find(c.camera);
    const Eigen::Vector3d p = rc ? Eigen::Vector3d(rc->T_world_cam.translation()) : Eigen::Vector3d::Zero();
    std::fprintf(stderr, "  %-12s %-8s %6d %7d %8.3f %13.2f %14.4f   (%.3f, %.3f, %.3f)\n", c.camera.c_str(),
                 rc ? rc->role.c_str() : "?", c.views, c.points, c.rms_px, 1000 * c.sigma_position_m,
                 c.sigma_rotation_deg, p.x(), p.y(), p.z());
  }
}

void printSync(const SyncReport& s) {
  int decisive = 0;
  for (const PairSync& p : s.pairs) decisive += p.decisive;
  if (s.ok) {
    std::cerr << "rig sync: every checked camera in sync (" << decisive << " camera pairs agree, offsets searched +-"
              << s.max_offset << " frames)\n";
  }
  for (const CameraSync& c : s.cameras) {
    if (c.in_sync) continue;
    const int n = std::abs(c.offset_frames);
    std::cerr << "rig sync: " << c.camera << " is OUT OF SYNC by " << c.offset_frames << " frame" << (n == 1 ? "" : "s")
              << " (" << (c.offset_frames > 0 ? "late: its frame f shows frame f - " : "early: its frame f shows frame f + ")
              << n << " of the others; pose spread " << fmt("%.3f", c.spread_at_offset) << " m at that offset vs "
              << (c.spread_at_zero < 0 ? std::string("n/a") : fmt("%.3f", c.spread_at_zero) + " m") << " at 0, "
              << c.pairs << " pairs)\n";
  }
  for (const std::string& name : s.unchecked) {
    std::cerr << "rig sync: " << name << " not checked (shares too few moving-board frames with the others)\n";
  }
}

void printCheck(const RigCheckResult& c, double flag_px) {
  std::fprintf(stderr, "  %-12s %6s %7s %8s %8s %9s  %s\n", "camera", "views", "points", "rms px", "median", "outliers",
               "status");
  for (const RigCheckCamera& cam : c.cameras) {
    std::fprintf(stderr, "  %-12s %6d %7d %8.3f %8.3f %9d  %s\n", cam.camera.c_str(), cam.views, cam.points,
                 cam.rms_px, cam.median_px, cam.outliers,
                 cam.flagged ? ("FLAGGED: " + cam.reason).c_str() : "ok");
  }
  std::cerr << "rig check: reprojection " << (c.ok ? "ok" : "FAILED") << " (flag above " << flag_px << " px)\n";
}

fs::path stemOf(const fs::path& out) { return fs::path(out).replace_extension(""); }

std::vector<std::string> sortedIntersection(const std::vector<std::string>& take_cameras, const Rig& rig) {
  std::vector<std::string> out;
  for (const std::string& name : take_cameras) {
    if (rig.find(name)) out.push_back(name);
    else std::cerr << "rig: " << name << " is in the take but not in the rig; left out\n";
  }
  if (out.empty()) throw Error("rig: no camera of the take is in the rig");
  return out;
}

// ---------------------------------------------------------------------------------------------
// Verbs

int runCalibrate(const RigArgs& a) {
  requireTake(a);
  const BoardSpec board = boardOf(a);
  const std::optional<FloorSpec> floor = floorOf(a);
  const std::vector<std::string> cameras = takeCameras(a.take);
  std::vector<std::string> estimate = splitList(a.estimate);
  for (std::string& e : estimate) {
    if (e == "all") e = "*";
  }
  RigPipelineOptions pipeline;
  pipeline.detect = detectOptions(a);
  pipeline.observations_cache = a.observations;
  RigCalibOptions& options = pipeline.calib;
  options.estimate_intrinsics = estimate;
  options.threads = a.threads;
  pipeline.sync.max_offset = a.max_offset;
  pipeline.sync.threads = a.threads;
  pipeline.validate();
  RigTake take;
  take.take = a.take;
  take.cameras = cameras;
  take.board = board;
  take.floor = floor;
  take.main_camera = a.main_camera;
  take.known = resolveIntrinsics(a, cameras, estimate);  // before detection: a missing file fails at once
  std::optional<Rig> compare;
  if (!a.compare.empty()) compare = readRig(a.compare);

  // Detect (or the --observations cache) -> initial rig -> solve -> sync check, as one library
  // call (multicam/pipeline.h). Throws (naming the camera) on a camera the solve cannot place;
  // nothing is written then.
  std::unique_ptr<ProgressLine> progress;
  const RigPipelineResult solved = calibrateRigTake(take, pipeline, [&](const DetectProgress& p) {
    if (!progress) progress = std::make_unique<ProgressLine>("rig detect", p.images_total, a.quiet);
    progress->update(p.images_done);
  });
  progress.reset();
  for (const std::string& line : solved.log) std::cerr << "rig: " << line << "\n";
  const RigObservations& obs = solved.observations;
  const double detect_s = solved.detect_s;
  const bool cached = solved.cached;
  printDetections(obs, detect_s, cached);
  const RigCalibResult& result = solved.calib;
  printCalib(result);
  const SyncReport& sync = solved.sync;
  printSync(sync);

  const fs::path out(a.out);
  writeRig(result.rig, out);
  const fs::path report_path = a.report.empty() ? fs::path(stemOf(out).string() + ".report.json") : fs::path(a.report);
  nlohmann::json report = {{"command", "rig calibrate"},
                           {"take", a.take},
                           {"out", out.string()},
                           {"calibration", reportToJson(result)},
                           {"sync", syncToJson(sync)},
                           {"detect", detectSummary(obs, detect_s, cached)}};
  std::vector<std::string> written = {out.string(), report_path.string()};
  if (!a.yaml_dir.empty()) {
    for (const fs::path& p : writeRigYaml(result.rig, a.yaml_dir)) written.push_back(p.string());
  }
  if (!a.picture.empty()) {
    RigPictureOptions picture_options;
    const RigPicture picture = writeRigPicture(result.rig, floor ? &*floor : nullptr, a.picture, picture_options);
    written.push_back(picture.png.string());
    written.push_back(picture.svg.string());
    report["picture"] = {{"png", picture.png.string()}, {"svg", picture.svg.string()},
                         {"max_coverage", picture.max_coverage}};
  }
  if (compare) {
    report["compare"] = compareRigs(result.rig, *compare);
    report["compare"]["with"] = a.compare;
    printCompare(report["compare"], a.compare);
  }
  writeJsonAtomic(report_path, report);
  std::cerr << "rig calibrate: wrote";
  for (const std::string& w : written) std::cerr << " " << w;
  std::cerr << "\n";
  if (a.json) {
    // The summary: per-camera figures without covariances or pair lists.
    nlohmann::json cams = report["calibration"]["cameras"];
    for (auto& c : cams) c.erase("covariance"), c.erase("covariance_order");
    nlohmann::json summary = {{"command", "rig calibrate"},
                              {"out", out.string()},
                              {"report", report_path.string()},
                              {"cameras", cams},
                              {"rms_px", result.rms_px},
                              {"residuals", result.residuals},
                              {"rejected", result.rejected},
                              {"world_from_floor", result.world_from_floor},
                              {"solve_ms", result.solve_ms},
                              {"detect", detectSummary(obs, detect_s, cached)},
                              {"sync_ok", sync.ok},
                              {"sync", report["sync"]["cameras"]}};
    summary["detect"].erase("cameras");
    if (compare) summary["compare"] = report["compare"];
    std::cout << summary.dump() << "\n";
  }
  return 0;
}

int runCheck(const RigArgs& a) {
  requireTake(a);
  const Rig rig = readRig(a.rig);
  const BoardSpec board = boardOf(a);
  const std::optional<FloorSpec> floor = floorOf(a);
  if (!(a.flag_px > 0)) throw flagError("--flag-px", "rig check: --flag-px must be > 0");
  const std::vector<std::string> cameras = sortedIntersection(takeCameras(a.take), rig);
  double detect_s = 0;
  bool cached = false;
  const RigObservations obs = observe(a, cameras, board, floor, &detect_s, &cached);
  printDetections(obs, detect_s, cached);
  const RigCheckResult check = checkRig(rig, obs, a.flag_px);
  printCheck(check, a.flag_px);
  SyncOptions sync_options;
  sync_options.max_offset = a.max_offset;
  sync_options.threads = a.threads;
  const SyncReport sync = checkSync(obs, rig, sync_options);
  printSync(sync);
  const bool ok = check.ok && sync.ok;
  std::cerr << "rig check: " << (ok ? "rig OK" : "PROBLEMS FOUND (exit 3)") << "\n";
  nlohmann::json report = {{"command", "rig check"}, {"take", a.take},  {"rig", a.rig},
                           {"ok", ok},               {"reprojection", checkToJson(check)},
                           {"sync", syncToJson(sync)}, {"detect", detectSummary(obs, detect_s, cached)}};
  if (!a.report.empty()) writeJsonAtomic(a.report, report);
  if (a.json) {
    report["detect"].erase("cameras");
    report["sync"].erase("pairs");
    std::cout << report.dump() << "\n";
  }
  return ok ? 0 : kExitCheckFailed;
}

int runResurvey(const RigArgs& a) {
  requireTake(a);
  const Rig rig = readRig(a.rig);
  rig.at(a.camera);  // names the camera when it is not in the rig
  const BoardSpec board = boardOf(a);
  const std::optional<FloorSpec> floor = floorOf(a);
  const std::vector<std::string> cameras = sortedIntersection(takeCameras(a.take), rig);
  if (std::find(cameras.begin(), cameras.end(), a.camera) == cameras.end()) {
    ErrorContext context;
    context.camera = a.camera;
    context.file = a.take;
    throw Error("rig resurvey: the take has no images of the camera", context);
  }
  RigCalibOptions options;
  options.estimate_intrinsics = splitList(a.estimate);
  options.threads = a.threads;
  options.validate();
  std::optional<Rig> compare;
  if (!a.compare.empty()) compare = readRig(a.compare);
  double detect_s = 0;
  bool cached = false;
  const RigObservations obs = observe(a, cameras, board, floor, &detect_s, &cached);
  printDetections(obs, detect_s, cached);
  const ResurveyResult r = resurveyCamera(rig, a.camera, obs, options);
  std::cerr << "rig resurvey: " << a.camera << " moved " << fmt("%.1f", 1000 * r.moved_m) << " mm and turned "
            << fmt("%.3f", r.rotated_deg) << " deg; " << r.report.views << " views, RMS " << fmt("%.3f", r.report.rms_px)
            << " px, sigma " << fmt("%.2f", 1000 * r.report.sigma_position_m) << " mm / "
            << fmt("%.4f", r.report.sigma_rotation_deg) << " deg\n";
  writeRig(r.rig, a.out);
  std::vector<std::string> written = {a.out};
  if (!a.yaml_dir.empty()) {
    Rig one;
    one.cameras.push_back(r.after);
    for (const fs::path& p : writeRigYaml(one, a.yaml_dir)) written.push_back(p.string());
  }
  nlohmann::json summary = {{"command", "rig resurvey"},
                            {"camera", a.camera},
                            {"out", a.out},
                            {"moved_m", r.moved_m},
                            {"rotated_deg", r.rotated_deg},
                            {"views", r.report.views},
                            {"points", r.report.points},
                            {"rejected", r.report.rejected},
                            {"rms_px", r.report.rms_px},
                            {"sigma_position_m", r.report.sigma_position_m},
                            {"sigma_rotation_deg", r.report.sigma_rotation_deg},
                            {"position_m", {r.after.T_world_cam.translation().x(), r.after.T_world_cam.translation().y(),
                                            r.after.T_world_cam.translation().z()}},
                            {"detect", detectSummary(obs, detect_s, cached)}};
  summary["detect"].erase("cameras");
  if (compare) {
    Rig mine;
    mine.cameras.push_back(r.after);
    summary["compare"] = compareRigs(mine, *compare);
    summary["compare"]["with"] = a.compare;
    printCompare(summary["compare"], a.compare);
  }
  if (!a.report.empty()) {
    writeJsonAtomic(a.report, summary);
    written.push_back(a.report);
  }
  std::cerr << "rig resurvey: wrote";
  for (const std::string& w : written) std::cerr << " " << w;
  std::cerr << "\n";
  if (a.json) std::cout << summary.dump() << "\n";
  return 0;
}

void addInputs(CLI::App* cmd, RigArgs& a) {
  cmd->add_option("--take", a.take, "Take folder (cams/: a sequence or video per camera; docs/formats.md \"Take folder\")")->required();
  cmd->add_option("--board", a.board, "Board waved through the volume (board JSON; default <take>/board.json)");
  cmd->add_option("--floor", a.floor,
                  "Floor-board frames and pose, floor.json (docs/formats.md; default <take>/floor.json when present)");
  cmd->add_flag("--no-floor", a.no_floor, "Ignore <take>/floor.json");
  cmd->add_option("--observations", a.observations,
                  "Board detections cache (JSON): written after detection, reused when it matches the take");
  cmd->add_option("--max-offset", a.max_offset, "Sync check: frames searched each way")->capture_default_str();
  cmd->add_flag("--not-srgb", a.not_srgb, "Images are not sRGB-encoded (calib/detect.h)");
  cmd->add_option("--threads", a.threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_flag("--json", a.json, "Print a JSON summary on stdout");
  cmd->add_flag("--quiet", a.quiet, "No progress line");
}

}  // namespace

Runner addRigCommand(CLI::App& app) {
  auto a = std::make_shared<RigArgs>();
  CLI::App* cmd = app.add_subcommand(
      "rig", "Calibrate all cameras of a stage in one world frame; check a rig; re-survey a bumped camera");
  cmd->require_subcommand(1);
  const std::string codes =
      "\nExit codes: 0 success; 1 error (message names the file, camera or flag); 2 bad command line";

  CLI::App* cal = cmd->add_subcommand(
      "calibrate",
      "Joint calibration from a rig take (board waved through the volume, floor board for the world frame)");
  addInputs(cal, *a);
  cal->add_option("--out", a->out, "rig.json to write (written only when the solve succeeds)")->required();
  cal->add_option("--intrinsics", a->intrinsics,
                  "Intrinsics: a rig.json, or a folder of <camera>.json (previz calib intrinsics) / <camera>.yaml");
  cal->add_option("--estimate-intrinsics", a->estimate,
                  "Refine these cameras' intrinsics in the solve: NAME,NAME or all");
  cal->add_option("--lens", a->lens, "Lens table (calib lens JSON) for the main camera");
  cal->add_option("--focus", a->focus, "Lens table focus value")->each([a](const std::string&) { a->has_focus = true; });
  cal->add_option("--zoom", a->zoom, "Lens table zoom value")->each([a](const std::string&) { a->has_zoom = true; });
  cal->add_option("--main-camera", a->main_camera, "Name of the main camera")->capture_default_str();
  cal->add_option("--yaml", a->yaml_dir, "Also write <dir>/<camera>.yaml (OpenCV: K, distortion, R, t world->camera)");
  cal->add_option("--picture", a->picture, "Write <stem>.png and <stem>.svg: top/side view, frusta, coverage");
  cal->add_option("--report", a->report, "Report JSON (default <out stem>.report.json)");
  cal->add_option("--compare", a->compare, "Print each camera's difference to this rig (e.g. a previous calibration)");
  cal->footer(codes + ". An out-of-sync camera is reported (and in --json) but does not change the exit code.\n");

  CLI::App* chk = cmd->add_subcommand(
      "check", "Reprojection and frame-sync report of a calibrated rig on a new capture of the board");
  addInputs(chk, *a);
  chk->add_option("--rig", a->rig, "Calibrated rig.json")->required();
  chk->add_option("--flag-px", a->flag_px, "Flag a camera whose reprojection RMS exceeds this")->capture_default_str();
  chk->add_option("--report", a->report, "Also write the report JSON here");
  chk->footer(codes + "; 3 the check found a problem: a camera flagged (bumped, wrong calibration) or out of sync.\n");

  CLI::App* rs = cmd->add_subcommand(
      "resurvey", "Re-solve one bumped camera against the others from a short new capture");
  addInputs(rs, *a);
  rs->add_option("--rig", a->rig, "Current rig.json")->required();
  rs->add_option("--camera", a->camera, "Camera to re-survey")->required();
  rs->add_option("--out", a->out, "rig.json to write (may equal --rig; written only on success)")->required();
  rs->add_option("--estimate-intrinsics", a->estimate, "Also refine the camera's intrinsics (its name)");
  rs->add_option("--yaml", a->yaml_dir, "Also write <dir>/<camera>.yaml");
  rs->add_option("--report", a->report, "Also write the summary JSON here");
  rs->add_option("--compare", a->compare, "Print the camera's difference to this rig (e.g. the truth)");
  rs->footer(codes + ".\n");

  return [a, cal, chk, rs]() {
    if (cal->parsed()) return runCalibrate(*a);
    if (chk->parsed()) return runCheck(*a);
    if (rs->parsed()) return runResurvey(*a);
    return 2;
  };
}

}  // namespace previz::app
