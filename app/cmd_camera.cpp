// previz camera: move cameras between previz's rig.json and the formats other tools use, and
// write ST maps for compositing packages.
#include <filesystem>
#include <iostream>
#include <optional>
#include <tuple>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "core/camera_io.h"
#include "core/distortion_maps.h"
#include "core/error.h"
#include "core/rig.h"
#include "core/rig_import.h"
#include "core/rig_world.h"
#include "multicam/floor_world.h"
#include "take/take.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct CameraArgs {
  // import
  std::string krt, projection, kalibr, colmap, size, take, out, units = "m", flip = "none", world;
  std::vector<std::string> opencv, names;
  // export / stmap / info
  std::string rig, opencv_dir, krt_out, projection_out, kalibr_out, colmap_out, camera, stmap_dir;
  double overscan = 0.0;
  bool fit_scale = false, json = false;
};

int runImport(const CameraArgs& a) {
  const int sources = !a.krt.empty() + !a.projection.empty() + !a.opencv.empty() + !a.kalibr.empty() +
                      !a.colmap.empty();
  if (sources != 1) throw Error("give exactly one of --opencv, --kalibr, --colmap, --krt, --projection");
  ImportOptions opt;
  if (!a.size.empty()) std::tie(opt.width, opt.height) = parseSize(a.size, "--size");
  // Sizes the files lack from the take's images of each camera (take/take.h: its first frame).
  if (!a.take.empty()) {
    if (!fs::is_directory(a.take)) throw Error("take folder not found", fileContext(a.take, "--take"));
    const fs::path dir = a.take;
    opt.size_of = [dir](const std::string& camera) -> std::optional<std::pair<int, int>> {
      take::TakeOptions one;
      one.cameras = {camera};
      const take::Take t(dir, one);
      const take::CameraStream& s = t.stream(camera);
      if (!s.usable() || s.width <= 0) return std::nullopt;
      return std::make_pair(s.width, s.height);
    };
  }
  opt.units = a.units;
  opt.flip = a.flip;
  opt.names = a.names;
  RigImport imported;
  if (!a.opencv.empty()) {
    imported = importOpenCv(std::vector<fs::path>(a.opencv.begin(), a.opencv.end()), opt);
  } else if (!a.kalibr.empty()) {
    imported = importKalibr(a.kalibr, opt);
  } else if (!a.colmap.empty()) {
    imported = importColmap(a.colmap, opt);
  } else {
    if (a.size.empty() && a.take.empty())
      throw Error("K R t and P rows carry no image size: give --size WxH or --take DIR", fieldContext("--size"));
    imported = !a.krt.empty() ? importKRtRows(a.krt, opt) : importProjectionRows(a.projection, opt);
  }
  // --world: the rig moved into previz's world from points known in both frames, or from the
  // floor board a take shows (core/rig_world.h, multicam/floor_world.h); --fit-scale: the scale
  // of a rig without one (COLMAP) fitted to them too.
  if (a.fit_scale && a.world.empty())
    throw Error("fits the rig's scale to the points or floor board of --world: give --world",
                fieldContext("--fit-scale"));
  if (!a.world.empty()) {
    const size_t colon = a.world.find(':');
    const std::string kind = a.world.substr(0, colon), where = colon == std::string::npos ? "" : a.world.substr(colon + 1);
    if (where.empty() || (kind != "points" && kind != "floor"))
      throw Error("give points:FILE.json or floor:TAKE_DIR (got '" + a.world + "')", fieldContext("--world"));
    if (kind == "points") {
      WorldPoints points = readWorldPoints(where);
      points.fit_scale = points.fit_scale || a.fit_scale;
      placeImportByPoints(imported, points, opt);
    } else {
      multicam::FloorPlacementOptions floor;
      floor.fit_scale = a.fit_scale;
      multicam::placeImportOnFloor(imported, where, opt, floor);
    }
  }
  writeRig(imported.rig, a.out);
  std::cerr << imported.report.fullReport();
  std::cerr << "camera import: " << imported.rig.cameras.size() << " cameras -> " << a.out << "\n";
  if (a.json) {
    std::cout << nlohmann::json{{"command", "camera import"},
                                {"cameras", imported.rig.names()},
                                {"out", a.out},
                                {"report", imported.report.toJson()}}
                     .dump()
              << "\n";
  }
  return 0;
}

int runExport(const CameraArgs& a) {
  const Rig rig = readRig(a.rig);
  if (a.opencv_dir.empty() && a.krt_out.empty() && a.projection_out.empty() && a.kalibr_out.empty() &&
      a.colmap_out.empty())
    throw Error("give one or more of --opencv-dir, --kalibr, --colmap, --krt-out, --projection-out");
  std::vector<std::string> written;
  auto wrote = [&](const std::vector<fs::path>& files) {
    for (const fs::path& f : files) written.push_back(f.string());
  };
  if (!a.opencv_dir.empty()) wrote(exportOpenCv(rig, a.opencv_dir));
  if (!a.kalibr_out.empty()) {
    exportKalibr(rig, a.kalibr_out);
    written.push_back(a.kalibr_out);
  }
  if (!a.colmap_out.empty()) wrote(exportColmap(rig, a.colmap_out));
  if (!a.krt_out.empty()) {
    writeKRtRows(rig, a.krt_out);
    written.push_back(a.krt_out);
  }
  if (!a.projection_out.empty()) {
    writeProjectionRows(rig, a.projection_out);
    written.push_back(a.projection_out);
  }
  for (const auto& w : written) std::cerr << "camera export: wrote " << w << "\n";
  if (a.json) std::cout << nlohmann::json{{"command", "camera export"}, {"files", written}}.dump() << "\n";
  return 0;
}

int runStmap(const CameraArgs& a) {
  const Rig rig = readRig(a.rig);
  const Camera& lens = rig.at(a.camera).camera;
  const Camera pinhole = idealPinhole(lens, a.overscan);
  const fs::path dir(a.stmap_dir);
  // Undistort: read the plate (lens) into the ideal pinhole frame. Distort: read a CG render
  // (ideal pinhole with overscan) into the lens frame, which needs the inverse model.
  const cv::Mat undistort = makeUndistortMap(lens, pinhole);
  writeStMap(dir / (lens.name + "_undistort.exr"), undistort, cv::Size(lens.width, lens.height),
             "undistort: output is the ideal pinhole image, values index the distorted plate");
  const DistortMapResult distort = makeDistortMap(lens, pinhole);
  writeStMap(dir / (lens.name + "_distort.exr"), distort.map,
             cv::Size(pinhole.width, pinhole.height),
             "distort: output is the lens image, values index the ideal pinhole (CG) image");
  std::cerr << "camera stmap: " << lens.name << ": wrote undistort/distort ST maps to " << dir
            << " (pinhole " << pinhole.width << "x" << pinhole.height << ", "
            << distort.not_invertible << " pixels not invertible)\n";
  if (a.json) {
    std::cout << nlohmann::json{{"command", "camera stmap"},
                                {"camera", lens.name},
                                {"pinhole_size", {pinhole.width, pinhole.height}},
                                {"not_invertible", distort.not_invertible},
                                {"max_newton_iterations", distort.max_iterations}}
                     .dump()
              << "\n";
  }
  return 0;
}

int runInfo(const CameraArgs& a) {
  const Rig rig = readRig(a.rig);
  rig.validate();
  nlohmann::json cams = nlohmann::json::array();
  for (const RigCamera& rc : rig.cameras) {
    const Camera& c = rc.camera;
    const double r_max = c.maxInvertibleRadius();
    const Eigen::Vector3d centre = rc.T_world_cam.translation();
    std::cerr << c.name << " (" << rc.role << ") " << c.width << "x" << c.height << " fx " << c.fx
              << " fy " << c.fy << " c (" << c.cx << ", " << c.cy << ") k1 " << c.dist.k1
              << " centre (" << centre.transpose() << ") m, invertible radius "
              << (std::isfinite(r_max) ? std::to_string(r_max) : std::string("unbounded")) << "\n";
    cams.push_back({{"name", c.name},
                    {"role", rc.role},
                    {"invertible_radius", std::isfinite(r_max) ? nlohmann::json(r_max) : nlohmann::json(nullptr)},
                    {"centre_m", {centre.x(), centre.y(), centre.z()}}});
  }
  const std::vector<std::string> warnings = rigPoseWarnings(rig);
  for (const std::string& w : warnings) std::cerr << "WARNING: " << w << "\n";
  if (a.json)
    std::cout << nlohmann::json{{"command", "camera info"}, {"cameras", cams}, {"warnings", warnings}}.dump() << "\n";
  return 0;
}

}  // namespace

Runner addCameraCommand(CLI::App& app) {
  auto a = std::make_shared<CameraArgs>();
  CLI::App* cmd = app.add_subcommand(
      "camera", "Import/export cameras (OpenCV, Kalibr, COLMAP, K R t rows, P matrices), ST maps, info");
  cmd->require_subcommand(1);

  CLI::App* imp = cmd->add_subcommand(
      "import", "Build a rig.json from another tool's cameras, poses included; prints what it assumed");
  imp->add_option("--opencv", a->opencv,
                  "OpenCV FileStorage files (YAML/XML/JSON): camera_matrix, distortion_coefficients, "
                  "[image_width/height], [rvec+tvec | R+T]; or a stereo pair M1 D1 M2 D2 [R T]");
  imp->add_option("--name", a->names, "Camera names, one per camera in reading order (default: file stem, "
                                      "or its folder when stems repeat)");
  imp->add_option("--kalibr", a->kalibr, "Kalibr camchain.yaml (pinhole-radtan, T_cn_cnm1 chain; cam0 = world)");
  imp->add_option("--colmap", a->colmap, "COLMAP text model folder (cameras.txt + images.txt)");
  imp->add_option("--krt", a->krt, "Text rows: name k11..k33 r11..r33 t1 t2 t3 (Middlebury par.txt)");
  imp->add_option("--projection", a->projection, "Text rows: name p11..p34 (3x4 P = K[R|t])");
  imp->add_option("--size", a->size, "Image size WxH for files without one (rows; OpenCV files without image_width)");
  imp->add_option("--take", a->take,
                  "Else each camera's size from its images in this take folder (docs/formats.md \"Take folder\")");
  imp->add_option("--units", a->units, "Unit of the file's translations")
      ->check(CLI::IsMember({"mm", "cm", "m"}))
      ->capture_default_str();
  imp->add_option("--flip", a->flip,
                  "The file's world axes, turned into previz's z up: y-up (x,y,z)->(x,-z,y), z-down "
                  "(x,y,z)->(x,-y,-z), y-down (x,y,z)->(x,z,-y), none")
      ->check(CLI::IsMember({"none", "y-up", "z-down", "y-down"}))
      ->capture_default_str();
  imp->add_option("--world", a->world,
                  "Place the rig in previz's world (z up, floor z = 0): points:FILE.json (3+ points with "
                  "\"world\" metres and \"rig\" in the file's frame and --units; docs/formats.md) or "
                  "floor:TAKE_DIR (the floor board of TAKE_DIR/floor.json seen by the imported cameras)");
  imp->add_flag("--fit-scale", a->fit_scale,
                "With --world: fit the rig's scale too (a rig without metric scale: COLMAP, another "
                "reconstruction); floor: needs 2+ cameras seeing the board from places apart. Points: as "
                "\"fit_scale\": true in the file");
  imp->add_option("--out", a->out, "rig.json to write")->required();
  imp->add_flag("--json", a->json, "JSON summary (with the import report) on stdout");

  CLI::App* exp = cmd->add_subcommand("export", "Write a rig's cameras, poses included, for other tools");
  exp->add_option("--rig", a->rig, "rig.json")->required()->check(CLI::ExistingFile);
  exp->add_option("--opencv-dir", a->opencv_dir, "Folder for one OpenCV YAML per camera (with rvec/tvec)");
  exp->add_option("--kalibr", a->kalibr_out, "Kalibr camchain.yaml to write");
  exp->add_option("--colmap", a->colmap_out, "Folder for a COLMAP text model (cameras/images/points3D.txt)");
  exp->add_option("--krt-out", a->krt_out, "K R t rows file to write");
  exp->add_option("--projection-out", a->projection_out, "P rows file to write");
  exp->add_flag("--json", a->json, "JSON summary on stdout");

  CLI::App* st = cmd->add_subcommand("stmap", "Write undistort/distort ST maps (EXR) of a camera");
  st->add_option("--rig", a->rig, "rig.json")->required()->check(CLI::ExistingFile);
  st->add_option("--camera", a->camera, "Camera name")->required();
  st->add_option("--overscan", a->overscan, "Pinhole overscan fraction")->capture_default_str();
  st->add_option("--out", a->stmap_dir, "Output folder")->required();
  st->add_flag("--json", a->json, "JSON summary on stdout");

  CLI::App* info = cmd->add_subcommand("info", "Validate a rig.json and summarise its cameras");
  info->add_option("--rig", a->rig, "rig.json")->required()->check(CLI::ExistingFile);
  info->add_flag("--json", a->json, "JSON summary on stdout");

  return [a, imp, exp, st, info]() {
    if (imp->parsed()) return runImport(*a);
    if (exp->parsed()) return runExport(*a);
    if (st->parsed()) return runStmap(*a);
    if (info->parsed()) return runInfo(*a);
    return 2;
  };
}

}  // namespace previz::app
