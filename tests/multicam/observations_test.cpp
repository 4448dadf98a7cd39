// Rig observations: JSON round trip, floor.json, and board detection over a take folder with
// the failures a real take has (missing and corrupt frames, a frame of the wrong size, a camera
// folder that is not there).
#include "multicam/observations.h"

#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "calib/board_print.h"
#include "core/error.h"
#include "core/io.h"
#include "datasets/studio.h"
#include "scratch.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

RigObservations sample() {
  RigObservations obs;
  obs.board = synth::defaultBoard(BoardType::kCharuco);
  obs.frame_count = 12;
  obs.has_floor = true;
  obs.floor.board = synth::defaultBoard(BoardType::kChessboard);
  obs.floor.frames = {10, 11};
  obs.floor.T_world_board.translation() = Eigen::Vector3d(0.1, -0.2, 0.0);
  for (const char* name : {"witness01", "main"}) {
    CameraDetections c;
    c.camera = name;
    c.image_size = cv::Size(1280, 720);
    for (int f : {0, 3, 10}) {
      for (int id = 0; id < 7; ++id) {
        calib::Observation o;
        o.id = id * 3 + f;
        o.px = Eigen::Vector2d(100.0 + id * 1.0 / 3.0, 200.123456789012 + f);
        c.frames[f].push_back(o);
      }
    }
    c.failures[5] = "file 'x/000005.png': not an image";
    obs.cameras.push_back(c);
  }
  return obs;
}

void expectSame(const RigObservations& a, const RigObservations& b) {
  EXPECT_EQ(boardToJson(a.board), boardToJson(b.board));
  EXPECT_EQ(a.frame_count, b.frame_count);
  EXPECT_EQ(a.has_floor, b.has_floor);
  EXPECT_EQ(a.floor.frames, b.floor.frames);
  EXPECT_EQ(boardToJson(a.floor.board), boardToJson(b.floor.board));
  EXPECT_TRUE(a.floor.T_world_board.isApprox(b.floor.T_world_board, 0));
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (size_t i = 0; i < a.cameras.size(); ++i) {
    EXPECT_EQ(a.cameras[i].camera, b.cameras[i].camera);
    EXPECT_EQ(a.cameras[i].image_size, b.cameras[i].image_size);
    EXPECT_EQ(a.cameras[i].failures, b.cameras[i].failures);
    ASSERT_EQ(a.cameras[i].frames.size(), b.cameras[i].frames.size());
    for (const auto& [f, points] : a.cameras[i].frames) {
      const auto& other = b.cameras[i].frames.at(f);
      ASSERT_EQ(points.size(), other.size());
      for (size_t k = 0; k < points.size(); ++k) {
        EXPECT_EQ(points[k].id, other[k].id);
        EXPECT_EQ(points[k].px, other[k].px);  // bit-exact: the cache must not change a solve
      }
    }
  }
}

TEST(Observations, FileRoundTripIsBitExact) {
  const fs::path dir = test::scratchDir("multicam_obs", "roundtrip");
  const RigObservations obs = sample();
  writeObservations(obs, dir / "obs.json");
  expectSame(obs, readObservations(dir / "obs.json"));
  EXPECT_TRUE(readObservations(dir / "obs.json").isFloorFrame(11));
  EXPECT_FALSE(readObservations(dir / "obs.json").isFloorFrame(3));
}

TEST(Observations, MalformedPointNamesFileCameraAndFrame) {
  nlohmann::json j = observationsToJson(sample());
  j["cameras"][1]["frames"][1]["points"][0] = {1, "x", 2};
  try {
    observationsFromJson(j, "obs.json");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, "obs.json");
    EXPECT_EQ(e.context().camera, "main");
    EXPECT_EQ(e.context().frame, 3);
  }
  j = observationsToJson(sample());
  j["format"] = "something else";
  EXPECT_THROW(observationsFromJson(j, "obs.json"), Error);
}

TEST(Floor, BoardPathIsRelativeToFloorJsonAndPoseDefaults) {
  const fs::path dir = test::scratchDir("multicam_obs", "floor");
  const BoardSpec board = synth::defaultBoard(BoardType::kAprilGrid);
  writeBoard(board, dir / "board.json");
  fs::create_directories(dir / "sub");
  writeJsonAtomic(dir / "sub" / "floor.json", {{"board", "../board.json"}, {"frames", {7, 5, 7}}});
  const FloorSpec floor = readFloor(dir / "sub" / "floor.json");
  EXPECT_EQ(boardToJson(floor.board), boardToJson(board));
  EXPECT_EQ(floor.frames, (std::vector<int>{5, 7}));
  EXPECT_TRUE(floor.T_world_board.isApprox(FloorSpec::defaultFloorPose(), 0));

  // Written with the board inline, read back the same.
  FloorSpec moved = floor;
  moved.T_world_board.translation() = Eigen::Vector3d(1, 2, 0);
  writeFloor(moved, dir / "floor2.json");
  const FloorSpec back = readFloor(dir / "floor2.json");
  EXPECT_EQ(back.frames, moved.frames);
  EXPECT_TRUE(back.T_world_board.isApprox(moved.T_world_board, 0));
}

TEST(Floor, BadFilesNameTheField) {
  const fs::path dir = test::scratchDir("multicam_obs", "floor_bad");
  auto fieldOf = [&](const nlohmann::json& j) {
    writeJsonAtomic(dir / "floor.json", j);
    try {
      readFloor(dir / "floor.json");
    } catch (const Error& e) {
      EXPECT_EQ(e.context().file, (dir / "floor.json").string());
      return e.context().field;
    }
    return std::string("(no error)");
  };
  const nlohmann::json board = boardToJson(synth::defaultBoard(BoardType::kChessboard));
  EXPECT_EQ(fieldOf({{"board", board}}), "frames");
  EXPECT_EQ(fieldOf({{"board", board}, {"frames", {1, -2}}}), "frames");
  EXPECT_EQ(fieldOf({{"frames", {1}}}), "board");
  EXPECT_EQ(fieldOf({{"board", board}, {"frames", {1}}, {"T_world_board", {{"R", 1}, {"t", {0, 0, 0}}}}}), "T_world_board.R");
  // A board path that does not exist names that file.
  writeJsonAtomic(dir / "floor.json", {{"board", "nosuch.json"}, {"frames", {1}}});
  try {
    readFloor(dir / "floor.json");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nosuch.json"), std::string::npos) << e.what();
  }
}

// A printed board pasted on white paper: board point (x, y) lies exactly at
// ((x + margin) ppm - 0.5 + pad, (y + margin) ppm - 0.5 + pad) (calib/board_print.h).
constexpr double kPpm = 1000;
constexpr int kPad = 40;
cv::Mat boardImage(const BoardSpec& spec) {
  cv::Mat grey = calib::drawBoard(spec, kPpm);
  cv::Mat padded;
  cv::copyMakeBorder(grey, padded, kPad, kPad, kPad, kPad, cv::BORDER_CONSTANT, cv::Scalar(255));
  cv::Mat bgr;
  cv::cvtColor(padded, bgr, cv::COLOR_GRAY2BGR);
  cv::GaussianBlur(bgr, bgr, cv::Size(0, 0), 0.8);  // a lens is never sharper than a pixel
  return bgr;
}

TEST(DetectTake, FloorFramesUseTheFloorBoardAndBadFramesAreReported) {
  const fs::path take = test::scratchDir("multicam_obs", "take");
  const BoardSpec moving = synth::defaultBoard(BoardType::kCharuco);
  const BoardSpec floor_board = synth::defaultBoard(BoardType::kChessboard);
  const cv::Mat moving_img = boardImage(moving), floor_img = boardImage(floor_board);
  const cv::Size size(std::max(moving_img.cols, floor_img.cols) + 20, std::max(moving_img.rows, floor_img.rows) + 20);
  cv::Mat canvas(size, CV_8UC3, cv::Scalar(255, 255, 255));
  floor_img.copyTo(canvas(cv::Rect(0, 0, floor_img.cols, floor_img.rows)));
  cv::Mat moving_canvas(canvas.size(), CV_8UC3, cv::Scalar(255, 255, 255));
  moving_img.copyTo(moving_canvas(cv::Rect(0, 0, moving_img.cols, moving_img.rows)));
  for (const char* cam : {"a", "b"}) {
    writeImageAtomic(take / "cams" / cam / "000000.png", canvas);
    writeImageAtomic(take / "cams" / cam / "000001.png", moving_canvas);
    std::ofstream(take / "cams" / cam / "000002.png") << "not a png";
    // 000003.png missing
  }
  cv::Mat small;
  cv::resize(moving_canvas, small, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
  writeImageAtomic(take / "cams" / "b" / "000001.png", small);
  writeJsonAtomic(take / "take.json", {{"frames", 4}, {"cameras", {"a", "b"}}});

  EXPECT_EQ(takeCameras(take), (std::vector<std::string>{"a", "b"}));
  FloorSpec floor;
  floor.board = floor_board;
  floor.frames = {0};
  int calls = 0, last_done = 0, total = 0;
  const RigObservations obs = detectTake(take, takeCameras(take), moving, &floor, {},
                                         [&](const DetectProgress& p) {
                                           ++calls;
                                           last_done = std::max(last_done, p.images_done);
                                           total = p.images_total;
                                         });
  EXPECT_EQ(calls, 8);
  EXPECT_EQ(last_done, 8);
  EXPECT_EQ(total, 8);
  EXPECT_EQ(obs.frame_count, 4);
  ASSERT_EQ(obs.cameras.size(), 2u);
  const CameraDetections& a = obs.cameras[0];
  const CameraDetections& b = obs.cameras[1];
  EXPECT_EQ(a.image_size, canvas.size());
  // Floor frame: every chessboard corner, where the print puts it.
  ASSERT_TRUE(a.frames.count(0));
  const std::vector<BoardPoint> floor_points = boardPoints(floor_board);
  EXPECT_EQ(a.frames.at(0).size(), floor_points.size());
  double worst = 0;
  for (const calib::Observation& o : a.frames.at(0)) {
    const Eigen::Vector3d p = floor_points.at(o.id).p_board;
    const Eigen::Vector2d truth((p.x() + floor_board.margin_m) * kPpm - 0.5 + kPad,
                                (p.y() + floor_board.margin_m) * kPpm - 0.5 + kPad);
    worst = std::max(worst, (o.px - truth).norm());
  }
  EXPECT_LT(worst, 0.1);
  // Moving frame: the ChArUco board's corners.
  ASSERT_TRUE(a.frames.count(1));
  EXPECT_EQ(a.frames.at(1).size(), boardPoints(moving).size());
  // Corrupt and missing frames are failures with the file named; b's small frame too.
  ASSERT_EQ(a.failures.size(), 2u);
  EXPECT_NE(a.failures.at(2).find("000002.png"), std::string::npos) << a.failures.at(2);
  EXPECT_NE(a.failures.at(3).find("000003.png"), std::string::npos) << a.failures.at(3);
  ASSERT_EQ(b.failures.size(), 3u);
  EXPECT_NE(b.failures.at(1).find("image is"), std::string::npos) << b.failures.at(1);
  EXPECT_FALSE(b.frames.count(1));

  // Same result on one thread (parallel merge in index order).
  DetectTakeOptions serial;
  serial.threads = 1;
  expectSame(obs, detectTake(take, {"a", "b"}, moving, &floor, serial));

  // A camera folder that is not there names the camera and the folder.
  try {
    detectTake(take, {"a", "c"}, moving, &floor);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "c");
    EXPECT_NE(std::string(e.what()).find((take / "cams" / "c").string()), std::string::npos) << e.what();
  }
}

TEST(DetectTake, CamerasFromFoldersWhenNoTakeJson) {
  const fs::path take = test::scratchDir("multicam_obs", "folders");
  fs::create_directories(take / "cams" / "z");
  fs::create_directories(take / "cams" / "y");
  EXPECT_EQ(takeCameras(take), (std::vector<std::string>{"y", "z"}));
  EXPECT_THROW(takeCameras(take / "nosuch"), Error);
}

}  // namespace
}  // namespace previz::multicam
