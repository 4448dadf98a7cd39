// An imported rig placed in previz's world (core/rig_world.h): a rig written by another tool in
// its own frame (an arbitrary rigid motion away from previz's world, translations in mm) comes
// back to the true rig from four surveyed points; with fit_scale, from a rig of unknown scale;
// bad point sets are refused naming the file and field. Figures: run
//   build/tests/core/core_tests --gtest_filter='RigWorld*'
#include "core/rig_world.h"

#include <cmath>
#include <filesystem>
#include <iostream>
#include <string>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "scratch.h"

namespace fs = std::filesystem;

namespace previz {
namespace {

fs::path tmpDir(const std::string& name) { return test::scratchDir("core", "rig_world_" + name); }

// Three witnesses around a stage, previz's world (z up, floor z = 0).
Rig trueRig() {
  Rig rig;
  const Eigen::Vector3d eyes[3] = {{3.2, -1.1, 1.9}, {-0.7, 3.4, 2.6}, {-2.9, -2.2, 0.8}};
  for (int i = 0; i < 3; ++i) {
    RigCamera rc;
    rc.camera.name = "witness0" + std::to_string(i + 1);
    rc.camera.width = 1280;
    rc.camera.height = 720;
    rc.camera.fx = rc.camera.fy = 1000 + 50 * i;
    rc.camera.cx = 639.5;
    rc.camera.cy = 359.5;
    rc.T_world_cam = lookAt(eyes[i], {0.1, -0.2, 1.0});
    rig.cameras.push_back(rc);
  }
  return rig;
}

// The other tool's frame: turned about a skew axis, shifted, y up-ish; T_file_world.
Pose fileFromWorld() {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(12.5, -4.25, 7.75);
  return T;
}

// Four surveyed points (floor marks and a stand top), world metres; "rig" in the file's mm.
nlohmann::json pointsJson(const Pose& T_file_world, double file_units_per_metre) {
  const Eigen::Vector3d world[4] = {{0, 0, 0}, {2.0, 0, 0}, {0, 1.5, 0}, {-1.0, 1.0, 1.8}};
  const char* names[4] = {"origin", "x2m", "y1.5m", "stand"};
  nlohmann::json points = nlohmann::json::array();
  for (int i = 0; i < 4; ++i) {
    const Eigen::Vector3d f = (T_file_world * world[i]) * file_units_per_metre;
    points.push_back({{"name", names[i]}, {"world", {world[i].x(), world[i].y(), world[i].z()}}, {"rig", {f.x(), f.y(), f.z()}}});
  }
  return {{"points", points}};
}

// What the other tool wrote, as import returned it: the poses in its frame, in metres.
RigImport importedInFileFrame(const Pose& T_file_world, double scale) {
  RigImport imported;
  imported.rig = trueRig();
  for (RigCamera& rc : imported.rig.cameras) {
    rc.T_world_cam = T_file_world * rc.T_world_cam;
    rc.T_world_cam.translation() *= scale;
  }
  return imported;
}

void expectBackToTruth(const Rig& placed, double position_m, double rotation_rad, const char* what) {
  const Rig truth = trueRig();
  double dp = 0, dr = 0;
  for (size_t i = 0; i < truth.cameras.size(); ++i) {
    dp = std::max(dp, translationDistance(placed.cameras[i].T_world_cam, truth.cameras[i].T_world_cam));
    dr = std::max(dr, rotationDistance(placed.cameras[i].T_world_cam, truth.cameras[i].T_world_cam));
  }
  std::cout << what << ": worst camera " << dp << " m, " << dr << " rad from the truth\n";
  EXPECT_LE(dp, position_m) << what;
  EXPECT_LE(dr, rotation_rad) << what;
}

TEST(RigWorld, FourPointsBringAMovedMillimetreRigBackToTheTruth) {
  const fs::path dir = tmpDir("moved");
  // The other tool's files: OpenCV YAML per camera, poses in its frame, translations in mm.
  Rig file_rig = trueRig();
  for (RigCamera& rc : file_rig.cameras) {
    rc.T_world_cam = fileFromWorld() * rc.T_world_cam;
    rc.T_world_cam.translation() *= 1000.0;
  }
  const std::vector<fs::path> files = exportOpenCv(file_rig, dir / "yaml");
  writeJsonAtomic(dir / "points.json", pointsJson(fileFromWorld(), 1000.0));
  ImportOptions options;
  options.units = "mm";
  RigImport imported = importOpenCv(files, options);
  const WorldPlacement w = placeImportByPoints(imported, readWorldPoints(dir / "points.json"), options);
  // Exact points: what is left is the files' print precision (mm to ~1e-13 relative).
  expectBackToTruth(imported.rig, 1e-6, 1e-9, "4 exact points, mm");
  EXPECT_LT(w.rms_m, 1e-9);
  EXPECT_NEAR(w.implied_scale, 1.0, 1e-9);
  EXPECT_EQ(w.scale, 1.0);
  EXPECT_NE(imported.rig.world_frame.find("points.json"), std::string::npos);
  EXPECT_TRUE(imported.report.warnings.empty()) << imported.report.fullReport();
  EXPECT_NE(imported.report.fullReport().find("rigid"), std::string::npos) << imported.report.fullReport();
  EXPECT_NE(imported.report.fullReport().find("axes: previz's z up set by the points"), std::string::npos)
      << imported.report.fullReport();
}

TEST(RigWorld, NoisyPointsPlaceTheRigWithinTheirNoise) {
  // Points surveyed to +-2 mm: the cameras 3-4 m away land within a few mm and a tenth of a degree.
  nlohmann::json j = pointsJson(fileFromWorld(), 1.0);
  const double noise[4][3] = {{0.002, -0.001, 0.0015}, {-0.0015, 0.002, -0.001}, {0.001, 0.0015, -0.002}, {-0.002, -0.0015, 0.001}};
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) j["points"][i]["world"][k] = j["points"][i]["world"][k].get<double>() + noise[i][k];
  const fs::path file = tmpDir("noisy") / "points.json";
  writeJsonAtomic(file, j);
  RigImport imported = importedInFileFrame(fileFromWorld(), 1.0);
  const WorldPlacement w = placeImportByPoints(imported, readWorldPoints(file), ImportOptions{});
  expectBackToTruth(imported.rig, 0.01, 0.1 * M_PI / 180, "4 points, +-2 mm");
  EXPECT_GT(w.rms_m, 0.0005);
  EXPECT_LT(w.max_m, 0.005);
}

TEST(RigWorld, FitScaleRecoversARigOfUnknownScale) {
  nlohmann::json j = pointsJson(fileFromWorld(), 0.37);
  j["fit_scale"] = true;
  const fs::path file = tmpDir("scale") / "points.json";
  writeJsonAtomic(file, j);
  RigImport imported = importedInFileFrame(fileFromWorld(), 0.37);
  const WorldPlacement w = placeImportByPoints(imported, readWorldPoints(file), ImportOptions{});
  EXPECT_NEAR(w.scale, 1.0 / 0.37, 1e-9);
  expectBackToTruth(imported.rig, 1e-9, 1e-9, "fit_scale, rig at 0.37");
}

TEST(RigWorld, AWrongUnitIsWarnedAboutNotHidden) {
  const fs::path file = tmpDir("units") / "points.json";
  writeJsonAtomic(file, pointsJson(fileFromWorld(), 1000.0));  // the file is in mm...
  RigImport imported = importedInFileFrame(fileFromWorld(), 10.0);
  ImportOptions options;
  options.units = "cm";  // ... said to be cm
  placeImportByPoints(imported, readWorldPoints(file), options);
  const std::string report = imported.report.fullReport();
  EXPECT_NE(report.find("scale of 0.1000"), std::string::npos) << report;
  EXPECT_NE(report.find("--units cm"), std::string::npos) << report;
}

TEST(RigWorld, BadPointSetsNameTheFileAndField) {
  const fs::path dir = tmpDir("bad");
  auto fieldOf = [&](const nlohmann::json& j, const ImportOptions& options = {}) -> ErrorContext {
    const fs::path file = dir / "p.json";
    writeJsonAtomic(file, j);
    try {
      RigImport imported = importedInFileFrame(fileFromWorld(), 1.0);
      placeImportByPoints(imported, readWorldPoints(file), options);
    } catch (const Error& e) {
      std::cout << e.what() << "\n";
      return e.context();
    }
    ADD_FAILURE() << j.dump();
    return {};
  };
  nlohmann::json two = pointsJson(fileFromWorld(), 1.0);
  two["points"].erase(2);
  two["points"].erase(2);
  EXPECT_EQ(fieldOf(two).field, "points");
  EXPECT_EQ(fieldOf(two).file, (dir / "p.json").string());
  nlohmann::json collinear = pointsJson(fileFromWorld(), 1.0);
  collinear["points"][2]["world"] = {4.0, 0.0, 0.0};
  collinear["points"][2]["rig"] = collinear["points"][1]["rig"];
  for (int k = 0; k < 3; ++k)  // the rig point twice as far along the same line
    collinear["points"][2]["rig"][k] = 2 * collinear["points"][1]["rig"][k].get<double>() -
                                       collinear["points"][0]["rig"][k].get<double>();
  collinear["points"].erase(3);
  EXPECT_EQ(fieldOf(collinear).field, "points");
  nlohmann::json missing = pointsJson(fileFromWorld(), 1.0);
  missing["points"][1].erase("rig");
  EXPECT_EQ(fieldOf(missing).field, "points[1] 'x2m'.rig");
  nlohmann::json repeated = pointsJson(fileFromWorld(), 1.0);
  repeated["points"][3]["name"] = "origin";
  EXPECT_EQ(fieldOf(repeated).field, "points[3] 'origin'");
  ImportOptions flipped;
  flipped.flip = "y-up";
  EXPECT_EQ(fieldOf(pointsJson(fileFromWorld(), 1.0), flipped).field, "flip");
}

}  // namespace
}  // namespace previz
