// previz camera: move cameras between previz's rig.json and the formats other tools use, and
// write ST maps for compositing packages.
#include <filesystem>
#include <iostream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "core/camera_io.h"
#include "core/distortion_maps.h"
#include "core/error.h"
#include "core/rig.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct CameraArgs {
  // import
  std::string krt, projection, size, out;
  std::vector<std::string> opencv;
  // export / stmap / info
  std::string rig, opencv_dir, krt_out, camera, stmap_dir;
  double overscan = 0.0;
  bool json = false;
};

int runImport(const CameraArgs& a) {
  const int sources = !a.krt.empty() + !a.projection.empty() + !a.opencv.empty();
  if (sources != 1) {
    throw Error("give exactly one of --krt, --projection, --opencv");
  }
  Rig rig;
  if (!a.opencv.empty()) {
    for (const std::string& path : a.opencv) {
      RigCamera rc;
      rc.camera = readOpenCvCamera(path, fs::path(path).stem().string());
      rig.cameras.push_back(rc);
    }
  } else {
    if (a.size.empty()) {
      throw Error("K R t and P rows carry no image size: give --size WxH", fieldContext("--size"));
    }
    const auto [w, h] = parseSize(a.size, "--size");
    rig = !a.krt.empty() ? readKRtRows(a.krt, w, h) : readProjectionRows(a.projection, w, h);
  }
  rig.validate();
  writeRig(rig, a.out);
  std::cerr << "camera import: " << rig.cameras.size() << " cameras -> " << a.out << "\n";
  if (a.json) {
    std::cout << nlohmann::json{{"command", "camera import"}, {"cameras", rig.names()},
                                {"out", a.out}}.dump()
              << "\n";
  }
  return 0;
}

int runExport(const CameraArgs& a) {
  const Rig rig = readRig(a.rig);
  if (a.opencv_dir.empty() && a.krt_out.empty()) {
    throw Error("give --opencv-dir and/or --krt-out");
  }
  std::vector<std::string> written;
  if (!a.opencv_dir.empty()) {
    for (const RigCamera& rc : rig.cameras) {
      const fs::path path = fs::path(a.opencv_dir) / (rc.camera.name + ".yaml");
      writeOpenCvCamera(rc.camera, path);
      written.push_back(path.string());
    }
  }
  if (!a.krt_out.empty()) {
    writeKRtRows(rig, a.krt_out);
    written.push_back(a.krt_out);
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
  if (a.json) std::cout << nlohmann::json{{"command", "camera info"}, {"cameras", cams}}.dump() << "\n";
  return 0;
}

}  // namespace

Runner addCameraCommand(CLI::App& app) {
  auto a = std::make_shared<CameraArgs>();
  CLI::App* cmd = app.add_subcommand(
      "camera", "Import/export cameras (OpenCV YAML, K R t rows, P matrices), ST maps, info");
  cmd->require_subcommand(1);

  CLI::App* imp = cmd->add_subcommand("import", "Build a rig.json from another tool's cameras");
  imp->add_option("--krt", a->krt, "Text rows: name k11..k33 r11..r33 t1 t2 t3 (Middlebury par.txt)");
  imp->add_option("--projection", a->projection, "Text rows: name p11..p34 (3x4 P = K[R|t])");
  imp->add_option("--opencv", a->opencv, "OpenCV calibration YAML/XML files (one per camera)");
  imp->add_option("--size", a->size, "Image size WxH (needed for --krt/--projection)");
  imp->add_option("--out", a->out, "rig.json to write")->required();
  imp->add_flag("--json", a->json, "JSON summary on stdout");

  CLI::App* exp = cmd->add_subcommand("export", "Write a rig's cameras for other tools");
  exp->add_option("--rig", a->rig, "rig.json")->required()->check(CLI::ExistingFile);
  exp->add_option("--opencv-dir", a->opencv_dir, "Folder for one OpenCV YAML per camera");
  exp->add_option("--krt-out", a->krt_out, "K R t rows file to write");
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
