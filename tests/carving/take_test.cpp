// Reading a take for carving (carving/take.h): rig.json and other tools' rows, frames found,
// bad frames dropped with the reason, masks thresholded, main-camera poses per frame.
#include "carving/take.h"

#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "core/pose.h"
#include "scratch.h"

namespace previz::carving {
namespace {
namespace fs = std::filesystem;

// Two witnesses and a main camera looking at the origin; sizes differ per camera.
Rig smallRig() {
  Rig rig;
  const std::pair<const char*, Eigen::Vector3d> eyes[] = {
      {"w1", {3, 0, 1.5}}, {"w2", {0, 3, 1.5}}, {"main", {-3, -1, 1.6}}};
  for (const auto& [name, eye] : eyes) {
    RigCamera rc;
    rc.camera.name = name;
    rc.camera.width = name == std::string("main") ? 48 : 40;
    rc.camera.height = name == std::string("main") ? 27 : 30;
    rc.camera.fx = rc.camera.fy = 50;
    rc.camera.cx = (rc.camera.width - 1) / 2.0;
    rc.camera.cy = (rc.camera.height - 1) / 2.0;
    rc.T_world_cam = lookAt(eye, Eigen::Vector3d(0, 0, 1));
    rc.role = name == std::string("main") ? "main" : "witness";
    rig.cameras.push_back(rc);
  }
  return rig;
}

void writePng(const fs::path& path, const cv::Mat& image) {
  fs::create_directories(path.parent_path());
  ASSERT_TRUE(cv::imwrite(path.string(), image)) << path;
}

// A take with frames 0..2 of every camera (plates: grey; masks: a ramp 0..255).
fs::path makeTake(const std::string& name, const Rig& rig) {
  const fs::path dir = test::scratchDir("carving_take", name);
  writeRig(rig, dir / "rig.json");
  for (const RigCamera& rc : rig.cameras) {
    for (int f = 0; f < 3; ++f) {
      char stem[16];
      std::snprintf(stem, sizeof(stem), "%06d.png", f);
      writePng(dir / "cams" / rc.camera.name / stem,
               cv::Mat(rc.camera.height, rc.camera.width, CV_8UC3, cv::Scalar(30, 200, 40)));
      cv::Mat ramp(rc.camera.height, rc.camera.width, CV_8UC1);
      for (int x = 0; x < ramp.cols; ++x) ramp.col(x).setTo(x * 255 / (ramp.cols - 1));
      writePng(dir / "masks" / rc.camera.name / stem, ramp);
    }
  }
  return dir;
}

TEST(Take, ReadsRigJsonFramesAndPlates) {
  const Rig rig = smallRig();
  const fs::path dir = makeTake("basic", rig);
  const Take take({dir, dir / "rig.json", {}, {}});
  EXPECT_EQ(take.rigFormat(), "rig.json");
  EXPECT_EQ(take.frames(), (std::vector<int>{0, 1, 2}));
  EXPECT_FALSE(take.hasMasks());
  const CameraFrame f = take.read("w2", 1);
  ASSERT_TRUE(f.ok()) << f.dropped;
  EXPECT_EQ(f.image.type(), CV_8UC3);
  EXPECT_EQ(f.image.size(), cv::Size(40, 30));
  EXPECT_TRUE(f.mask.empty());
  EXPECT_TRUE(take.cleanPlate("w1").empty());
}

TEST(Take, MissingTruncatedAndWrongSizeFramesDropTheCameraWithTheReason) {
  const Rig rig = smallRig();
  const fs::path dir = makeTake("bad", rig);
  fs::remove(dir / "cams/w1/000001.png");
  // A truncated PNG: the first 60 bytes of a good one (header, no image data).
  const std::string bytes = readTextFile(dir / "cams/w2/000002.png");
  writeFileAtomic(dir / "cams/w2/000002.png", bytes.substr(0, 60));
  writePng(dir / "cams/main/000000.png", cv::Mat(10, 10, CV_8UC3, cv::Scalar::all(0)));
  const Take take({dir, dir / "rig.json", {}, {}});
  EXPECT_EQ(take.frames(), (std::vector<int>{0, 1, 2}));  // w2 and main still have frame 1

  const CameraFrame missing = take.read("w1", 1);
  EXPECT_FALSE(missing.ok());
  EXPECT_NE(missing.dropped.find("missing frame"), std::string::npos) << missing.dropped;
  EXPECT_NE(missing.dropped.find("w1/000001.png"), std::string::npos) << missing.dropped;

  const CameraFrame corrupt = take.read("w2", 2);
  EXPECT_FALSE(corrupt.ok());
  EXPECT_NE(corrupt.dropped.find("unreadable frame"), std::string::npos) << corrupt.dropped;
  EXPECT_NE(corrupt.dropped.find("w2/000002.png"), std::string::npos) << corrupt.dropped;

  const CameraFrame small = take.read("main", 0);
  EXPECT_FALSE(small.ok());
  EXPECT_NE(small.dropped.find("10x10, the rig says 48x27"), std::string::npos) << small.dropped;

  EXPECT_TRUE(take.read("w1", 2).ok());  // the others are untouched
  EXPECT_THROW(take.read("nosuch", 0), Error);
}

TEST(Take, MasksAreThresholdedAbove127) {
  const Rig rig = smallRig();
  const fs::path dir = makeTake("masks", rig);
  const Take take({dir, dir / "rig.json", dir / "masks", {}});
  const CameraFrame f = take.read("w1", 0);
  ASSERT_TRUE(f.ok()) << f.dropped;
  ASSERT_EQ(f.mask.type(), CV_8UC1);
  EXPECT_TRUE(f.image.empty());  // masks replace keying: the plate is not read
  for (int x = 0; x < f.mask.cols; ++x) {
    const int value = x * 255 / (f.mask.cols - 1);
    EXPECT_EQ(f.mask.at<uchar>(0, x), value > 127 ? 255 : 0) << x;
  }
  fs::remove(dir / "masks/w2/000001.png");
  const CameraFrame m = take.read("w2", 1);
  EXPECT_NE(m.dropped.find("missing mask"), std::string::npos) << m.dropped;
}

TEST(Take, ProjectionAndKRtRowsGiveTheSameCamerasWithSizesFromTheImages) {
  const Rig rig = smallRig();
  const fs::path dir = makeTake("rows", rig);
  {
    std::ofstream p(dir / "cams.P.txt");
    p << "# name p11 .. p34\n";
    for (const RigCamera& rc : rig.cameras) {
      const Eigen::Matrix<double, 3, 4> P = projectionMatrix(rc);
      p << rc.camera.name;
      for (int i = 0; i < 12; ++i) p << " " << std::setprecision(17) << P(i / 4, i % 4);
      p << "\n";
    }
  }
  writeKRtRows(rig, dir / "cams.krt.txt");
  for (const char* file : {"cams.P.txt", "cams.krt.txt"}) {
    SCOPED_TRACE(file);
    const Take take({dir, dir / file, {}, {}});
    EXPECT_EQ(take.rigFormat(), file == std::string("cams.P.txt") ? "projection rows" : "K R t rows");
    ASSERT_EQ(take.rig().cameras.size(), rig.cameras.size());
    for (size_t i = 0; i < rig.cameras.size(); ++i) {
      const RigCamera& a = rig.cameras[i];
      const RigCamera& b = take.rig().cameras[i];
      EXPECT_EQ(b.camera.name, a.camera.name);
      EXPECT_EQ(b.camera.width, a.camera.width);  // from the images
      EXPECT_EQ(b.camera.height, a.camera.height);
      EXPECT_NEAR(b.camera.fx, a.camera.fx, 1e-9);
      EXPECT_NEAR(b.camera.cy, a.camera.cy, 1e-9);
      EXPECT_LT(translationDistance(a.T_world_cam, b.T_world_cam), 1e-9);
      EXPECT_LT(rotationDistance(a.T_world_cam, b.T_world_cam), 1e-9);
    }
  }
}

TEST(Take, MainPosesOverrideTheRigPerFrame) {
  const Rig rig = smallRig();
  const fs::path dir = makeTake("poses", rig);
  const Pose moved = lookAt(Eigen::Vector3d(-2.5, -1, 1.6), Eigen::Vector3d(0, 0, 1));
  writeFileAtomic(dir / "poses.jsonl",
                  nlohmann::json({{"frame", 1}, {"T_world_cam", poseToJson(moved)}}).dump() + "\n");
  const Take take({dir, dir / "rig.json", {}, dir / "poses.jsonl"});
  EXPECT_LT(translationDistance(take.cameraAt("main", 1).T_world_cam, moved), 1e-12);
  EXPECT_LT(translationDistance(take.cameraAt("main", 0).T_world_cam, rig.at("main").T_world_cam), 1e-12);
  EXPECT_LT(translationDistance(take.cameraAt("w1", 1).T_world_cam, rig.at("w1").T_world_cam), 1e-12);
}

TEST(Take, AMainPoseTheTrackerLostDropsTheMainCameraForThatFrame) {
  // `previz track camera`'s camera_poses.jsonl: frame 0 tracked, 1 lost, 2 a bad frame.
  const Rig rig = smallRig();
  const fs::path dir = makeTake("lost_poses", rig);
  const Pose moved = lookAt(Eigen::Vector3d(-2.5, -1, 1.6), Eigen::Vector3d(0, 0, 1));
  writeFileAtomic(dir / "camera_poses.jsonl",
                  nlohmann::json({{"frame", 0}, {"state", "tracked"}, {"T_world_cam", poseToJson(moved)}}).dump() +
                      "\n" +
                      nlohmann::json({{"frame", 1}, {"state", "lost"}, {"reason", "no studio tag seen"}}).dump() +
                      "\n" + nlohmann::json({{"frame", 2}, {"state", "bad frame"}, {"reason", "truncated"}}).dump() +
                      "\n");
  const Take take({dir, dir / "rig.json", {}, dir / "camera_poses.jsonl"});
  EXPECT_TRUE(take.hasMainPoses());
  EXPECT_LT(translationDistance(take.cameraAt("main", 0).T_world_cam, moved), 1e-12);
  EXPECT_TRUE(take.read("main", 0).ok());
  for (int f : {1, 2}) {
    for (const CameraFrame& c : {take.read("main", f), take.readPlate("main", f)}) {
      EXPECT_FALSE(c.ok());
      EXPECT_NE(c.dropped.find("no pose at this frame in"), std::string::npos) << c.dropped;
      EXPECT_NE(c.dropped.find("camera_poses.jsonl"), std::string::npos) << c.dropped;
      EXPECT_NE(c.dropped.find(f == 1 ? "no studio tag seen" : "truncated"), std::string::npos) << c.dropped;
    }
    EXPECT_TRUE(take.read("w1", f).ok());
  }
}

// Expects an Error whose context names 'field' or 'file'.
template <typename Fn>
void expectErrorNaming(Fn&& fn, const std::string& field, const std::string& file) {
  try {
    fn();
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    if (!field.empty()) {
      EXPECT_EQ(e.context().field, field) << e.what();
    }
    if (!file.empty()) {
      EXPECT_NE(e.context().file.find(file), std::string::npos) << e.what();
    }
  }
}

TEST(Take, BadInputsNameTheCulprit) {
  const Rig rig = smallRig();
  const fs::path dir = makeTake("errors", rig);
  expectErrorNaming([&] { Take({dir / "nosuch", dir / "rig.json", {}, {}}); }, "--take", "nosuch");
  expectErrorNaming([&] { Take({dir, dir / "nosuch.json", {}, {}}); }, "--rig", "nosuch.json");
  expectErrorNaming([&] { Take({dir, dir / "rig.json", dir / "nomasks", {}}); }, "--masks", "nomasks");
  writeFileAtomic(dir / "broken.json", "{\"units\": \"m\", \"cameras\": [ {\"name\": \"a\"");
  expectErrorNaming([&] { Take({dir, dir / "broken.json", {}, {}}); }, "", "broken.json");
  writeFileAtomic(dir / "short.txt", "w1 1 2 3\n");
  expectErrorNaming([&] { Take({dir, dir / "short.txt", {}, {}}); }, "row", "short.txt");
  writeFileAtomic(dir / "poses.jsonl", "{\"frame\": 1}\n");
  expectErrorNaming([&] { Take({dir, dir / "rig.json", {}, dir / "poses.jsonl"}); }, "", "poses.jsonl");
  const fs::path empty = test::scratchDir("carving_take", "empty");
  expectErrorNaming([&] { Take({empty, dir / "rig.json", {}, {}}); }, "--take", "empty");
}

}  // namespace
}  // namespace previz::carving
