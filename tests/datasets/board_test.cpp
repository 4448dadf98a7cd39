// Calibration boards: the spec (core/board.cpp: validate, size, points, JSON) and the drawn
// pattern (datasets/studio_board.cpp). Truth is boardPoints(); the drawn boards are checked by
// the detectors the calibration code uses (OpenCV chessboard / ArUco + ChArUco, libapriltag)
// on orthographic fronto-parallel renders traced through Scene.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <vector>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/board.h"
#include "core/error.h"
#include "core/io.h"
#include "datasets/studio.h"
#include "scratch.h"

namespace previz::synth {
namespace {

namespace fs = std::filesystem;

// Orthographic view of a board: pixel (u, v) (centre convention) sees board point
// (x0 + u * px, y0 + v * px); rays travel along the board's +z, i.e. onto the printed side.
struct OrthoView {
  double x0, y0, px;
  int width, height;
  Eigen::Vector2d toPixel(const Eigen::Vector3d& p_board) const {
    return {(p_board.x() - x0) / px, (p_board.y() - y0) / px};
  }
};

// A board pose that is not the identity, so the primitive's transforms are exercised.
Pose someBoardPose() {
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.4, -1.2, 1.3);
  return T;
}

// Traced grey image (sRGB-encoded mean of the channels). ss x ss samples per pixel on the
// canonical multi-jittered pattern: ss^2 distinct offsets along each axis, so an axis-aligned
// edge's coverage is quantised to 1 / ss^2 px (a position bias <= 0.03 px at ss = 4).
cv::Mat renderOrtho(const BoardSpec& spec, const Pose& T_world_board, const OrthoView& view, int ss = 4) {
  Scene scene;
  scene.add(makeBoard(spec, T_world_board));
  cv::Mat image(view.height, view.width, CV_8UC1);
  const Eigen::Vector3d dir = T_world_board.linear().col(2);
  const int n = ss * ss;
  for (int v = 0; v < view.height; ++v)
    for (int u = 0; u < view.width; ++u) {
      double sum = 0;
      for (int i = 0; i < ss; ++i)
        for (int j = 0; j < ss; ++j) {
          const double ox = (i * ss + j + 0.5) / n - 0.5, oy = (j * ss + i + 0.5) / n - 0.5;
          const double x = view.x0 + (u + ox) * view.px;
          const double y = view.y0 + (v + oy) * view.px;
          const Ray ray{T_world_board * Eigen::Vector3d(x, y, -0.5), dir};
          Hit hit;
          scene.trace(ray, hit);
          sum += hit.rgb.mean();
        }
      const double lin = sum / n;
      const double s = lin <= 0.0031308 ? 12.92 * lin : 1.055 * std::pow(lin, 1 / 2.4) - 0.055;
      image.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(std::lround(std::clamp(s, 0.0, 1.0) * 255));
    }
  return image;
}

// A view of the board and its white margin (nothing beyond: the scene's environment is dark).
OrthoView viewOf(const BoardSpec& spec, double px) {
  const Eigen::Vector2d size = spec.size_m();
  const double pad = spec.margin_m;
  OrthoView view;
  view.px = px;
  // Board edges fall at 0.37 / 0.81 px phases, not on pixel boundaries: anti-aliasing is
  // exercised, and a half-pixel convention error could not hide.
  view.x0 = -pad + 0.37 * px;
  view.y0 = -pad + 0.81 * px;
  view.width = static_cast<int>(std::floor((size.x() + 2 * pad) / px));
  view.height = static_cast<int>(std::floor((size.y() + 2 * pad) / px));
  return view;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

TEST(BoardSpec, PointsAndSizesFollowTheDocumentedLayout) {
  const BoardSpec chess = defaultBoard(BoardType::kChessboard);
  auto pts = boardPoints(chess);
  ASSERT_EQ(pts.size(), static_cast<size_t>((chess.rows - 1) * (chess.cols - 1)));
  EXPECT_EQ(pts[0].id, 0);
  EXPECT_TRUE(pts[0].p_board.isApprox(Eigen::Vector3d(chess.square_m, chess.square_m, 0)));
  EXPECT_EQ(pts.back().id, (chess.rows - 1) * (chess.cols - 1) - 1);
  EXPECT_TRUE(chess.size_m().isApprox(Eigen::Vector2d(chess.cols * chess.square_m, chess.rows * chess.square_m)));

  const BoardSpec grid = defaultBoard(BoardType::kAprilGrid);
  pts = boardPoints(grid);
  ASSERT_EQ(pts.size(), static_cast<size_t>(4 * grid.rows * grid.cols));
  const double s = grid.square_m, g = grid.marker_m;
  // Tag 0's bottom-left corner (as printed) and tag 1's top-left corner.
  EXPECT_TRUE(pts[0].p_board.isApprox(Eigen::Vector3d(g, g + s, 0)));
  EXPECT_TRUE(pts[4 + 3].p_board.isApprox(Eigen::Vector3d(2 * g + s, g, 0)));
  EXPECT_NEAR(grid.size_m().x(), grid.cols * s + (grid.cols + 1) * g, 1e-12);

  const BoardSpec circles = defaultBoard(BoardType::kCircles);
  pts = boardPoints(circles);
  ASSERT_EQ(pts.size(), static_cast<size_t>(circles.rows * circles.cols));
  EXPECT_TRUE(pts[circles.cols + 1].p_board.isApprox(Eigen::Vector3d(1.5 * circles.square_m, 1.5 * circles.square_m, 0)));
}

// Quadtree (core/board.h): 5 x 5 cells, 3 levels: ring 0 (16 cells) one marker each, ring 1
// (8 cells) 2 x 2, the centre cell 4 x 4; markers ordered by cell row-major, then sub-cell
// row-major; each centred in its (sub-)cell with edge marker_m / 2^level; corners tl, tr, br, bl.
TEST(BoardSpec, QuadtreeMarkersShrinkByChebyshevRing) {
  const BoardSpec q = defaultBoard(BoardType::kQuadtree);
  ASSERT_EQ(q.cols, 5);
  ASSERT_EQ(q.levels, 3);
  const double s = q.square_m, m = q.marker_m;
  const auto markers = quadtreeMarkers(q);
  ASSERT_EQ(markers.size(), 16u + 8 * 4 + 16);
  EXPECT_EQ(quadtreeLevel(q, 0, 3), 0);
  EXPECT_EQ(quadtreeLevel(q, 1, 3), 1);
  EXPECT_EQ(quadtreeLevel(q, 3, 1), 1);
  EXPECT_EQ(quadtreeLevel(q, 2, 2), 2);
  // Cell (0, 0): marker 0; cells (0, 1..4) markers 1-4; cell (1, 0) marker 5; cell (1, 1):
  // markers 6-9, its top-right sub-cell is marker 7.
  EXPECT_TRUE(markers[0].top_left.isApprox(Eigen::Vector2d::Constant(0.5 * (s - m))));
  EXPECT_NEAR(markers[0].edge_m, m, 1e-15);
  EXPECT_TRUE(markers[5].top_left.isApprox(Eigen::Vector2d(0.5 * (s - m), s + 0.5 * (s - m))));
  EXPECT_EQ(markers[7].level, 1);
  EXPECT_NEAR(markers[7].edge_m, m / 2, 1e-15);
  EXPECT_TRUE(markers[7].top_left.isApprox(
      Eigen::Vector2d(1.5 * s + 0.25 * (s - m), s + 0.25 * (s - m))));
  // The centre cell (2, 2) comes after 5 + 5 + 2 cells of ring 0 and 2 of ring 1 (row 1 has
  // 3 ring-1 cells): markers 5 + (1 + 3*4 + 1) + (1 + 4) = 24 onwards, 16 of them, edge m / 4.
  const int centre_first = 5 + (1 + 3 * 4 + 1) + (1 + 4);
  EXPECT_EQ(markers[centre_first].level, 2);
  EXPECT_EQ(markers[centre_first + 15].level, 2);
  EXPECT_EQ(markers[centre_first + 16].level, 1);
  EXPECT_TRUE(markers[centre_first].top_left.isApprox(
      Eigen::Vector2d::Constant(2 * s + 0.125 * (s - m))));
  EXPECT_TRUE(markers[centre_first + 15].top_left.isApprox(
      Eigen::Vector2d::Constant(3 * s - 0.25 * s + 0.125 * (s - m))));
  // Every marker inside its cell, none overlapping another (centres a cell apart at least).
  for (size_t i = 0; i < markers.size(); ++i) {
    const Eigen::Vector2d c = markers[i].top_left + Eigen::Vector2d::Constant(0.5 * markers[i].edge_m);
    for (size_t j = 0; j < i; ++j) {
      const Eigen::Vector2d d =
          markers[j].top_left + Eigen::Vector2d::Constant(0.5 * markers[j].edge_m) - c;
      EXPECT_GE(d.lpNorm<Eigen::Infinity>(),
                0.5 * (markers[i].cell_m + markers[j].cell_m) - 1e-12) << i << " " << j;
    }
  }
  const auto pts = boardPoints(q);
  ASSERT_EQ(pts.size(), 4 * markers.size());
  for (size_t i = 0; i < markers.size(); ++i) {
    const Eigen::Vector2d& p = markers[i].top_left;
    const double e = markers[i].edge_m;
    EXPECT_EQ(pts[4 * i + 2].id, static_cast<int>(4 * i + 2));
    EXPECT_TRUE(pts[4 * i + 0].p_board.isApprox(Eigen::Vector3d(p.x(), p.y(), 0)));
    EXPECT_TRUE(pts[4 * i + 1].p_board.isApprox(Eigen::Vector3d(p.x() + e, p.y(), 0)));
    EXPECT_TRUE(pts[4 * i + 2].p_board.isApprox(Eigen::Vector3d(p.x() + e, p.y() + e, 0)));
    EXPECT_TRUE(pts[4 * i + 3].p_board.isApprox(Eigen::Vector3d(p.x(), p.y() + e, 0)));
  }
  EXPECT_TRUE(q.size_m().isApprox(Eigen::Vector2d(5 * s, 5 * s)));
  // levels = 1: a plain grid of markers; a 6 x 6 board with 2 levels: ring 0 (20 cells), the
  // 16 inner cells split 2 x 2.
  BoardSpec plain = q;
  plain.levels = 1;
  EXPECT_EQ(quadtreeMarkers(plain).size(), 25u);
  BoardSpec even = q;
  even.rows = even.cols = 6;
  even.levels = 2;
  EXPECT_EQ(quadtreeMarkers(even).size(), 20u + 16 * 4);
}

TEST(BoardSpec, JsonRoundTripAndFileRoundTrip) {
  for (BoardType type : {BoardType::kChessboard, BoardType::kCharuco, BoardType::kAprilGrid,
                         BoardType::kCircles, BoardType::kQuadtree}) {
    BoardSpec spec = defaultBoard(type);
    spec.first_id = type == BoardType::kCharuco ? 100 : type == BoardType::kQuadtree ? 30 : 0;
    if (type == BoardType::kQuadtree) spec.levels = 2;
    const BoardSpec back = boardFromJson(boardToJson(spec));
    EXPECT_EQ(back.type, spec.type);
    EXPECT_EQ(back.rows, spec.rows);
    EXPECT_EQ(back.cols, spec.cols);
    EXPECT_EQ(back.square_m, spec.square_m);
    EXPECT_EQ(back.marker_m, spec.marker_m);
    EXPECT_EQ(back.circle_radius_m, spec.circle_radius_m);
    EXPECT_EQ(back.dictionary, spec.dictionary);
    EXPECT_EQ(back.first_id, spec.first_id);
    EXPECT_EQ(back.legacy_pattern, spec.legacy_pattern);
    EXPECT_EQ(back.margin_m, spec.margin_m);
    EXPECT_EQ(back.levels, spec.levels);
    const fs::path path = test::scratchDir("board_test", "specs") / (std::string(toString(type)) + ".json");
    writeBoard(spec, path);
    const BoardSpec file = readBoard(path);
    EXPECT_EQ(boardToJson(file), boardToJson(spec));
  }
}

TEST(BoardSpec, ValidateNamesTheBadField) {
  auto expectField = [](BoardSpec spec, const std::string& field) {
    try {
      spec.validate();
      ADD_FAILURE() << "no error for " << field;
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, field) << e.what();
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  BoardSpec b = defaultBoard(BoardType::kChessboard);
  b.square_m = -0.01;
  expectField(b, "square_m");
  b = defaultBoard(BoardType::kChessboard);
  b.rows = 2;
  expectField(b, "rows");
  b = defaultBoard(BoardType::kChessboard);
  b.legacy_pattern = true;
  expectField(b, "legacy_pattern");
  b = defaultBoard(BoardType::kCharuco);
  b.marker_m = b.square_m;
  expectField(b, "marker_m");
  b = defaultBoard(BoardType::kCharuco);
  b.dictionary = "DICT_5X5_9";
  expectField(b, "dictionary");
  b = defaultBoard(BoardType::kCharuco);
  b.first_id = 990;  // 35 markers past the 1000 codes
  expectField(b, "first_id");
  b = defaultBoard(BoardType::kAprilGrid);
  b.dictionary = "DICT_APRILTAG_36h11";
  expectField(b, "dictionary");
  b = defaultBoard(BoardType::kCircles);
  b.circle_radius_m = 0.5 * b.square_m;
  expectField(b, "circle_radius_m");
  b = defaultBoard(BoardType::kCircles);
  b.margin_m = -1;
  expectField(b, "margin_m");
  b = defaultBoard(BoardType::kQuadtree);
  b.rows = 4;
  expectField(b, "rows");  // rows must equal cols
  b = defaultBoard(BoardType::kQuadtree);
  b.levels = 0;
  expectField(b, "levels");
  b = defaultBoard(BoardType::kQuadtree);
  b.marker_m = b.square_m;
  expectField(b, "marker_m");
  b = defaultBoard(BoardType::kQuadtree);
  b.dictionary = "DICT_4X4_50";  // 64 markers
  expectField(b, "first_id");
  b = defaultBoard(BoardType::kQuadtree);
  b.first_id = 200;  // 64 markers past DICT_4X4_250's codes
  expectField(b, "first_id");
  b = defaultBoard(BoardType::kQuadtree);
  b.dictionary = "tag36h11";
  expectField(b, "dictionary");

  // JSON readers: wrong type and unknown board type name the field and the file.
  nlohmann::json j = boardToJson(defaultBoard(BoardType::kCharuco));
  j["rows"] = "seven";
  try {
    boardFromJson(j, "b.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "rows");
    EXPECT_EQ(e.context().file, "b.json");
  }
  j = boardToJson(defaultBoard(BoardType::kCharuco));
  j["type"] = "hexagons";
  try {
    boardFromJson(j, "b.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "type");
  }
  // Quadtree JSON: "levels" read, wrong type or out of range named; not allowed on others.
  j = boardToJson(defaultBoard(BoardType::kQuadtree));
  EXPECT_EQ(j.at("type"), "quadtree");
  EXPECT_EQ(j.at("levels"), 3);
  for (const nlohmann::json& bad : {nlohmann::json("3"), nlohmann::json(2.5), nlohmann::json(9)}) {
    j["levels"] = bad;
    try {
      boardFromJson(j, "q.json");
      ADD_FAILURE() << "no error for levels " << bad.dump();
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, "levels") << e.what();
      EXPECT_EQ(e.context().file, "q.json");
    }
  }
  j = boardToJson(defaultBoard(BoardType::kQuadtree));
  j["cols"] = 6;
  try {
    boardFromJson(j, "q.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "rows") << e.what();
  }
  j = boardToJson(defaultBoard(BoardType::kCharuco));
  j["levels"] = 2;
  try {
    boardFromJson(j, "b.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "levels") << e.what();
  }
  j = boardToJson(defaultBoard(BoardType::kCharuco));
  j["marker_m"] = 1.0;
  try {
    boardFromJson(j, "b.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "marker_m");
    EXPECT_EQ(e.context().file, "b.json");
  }
}

// AprilGrid layout and tag border: written and read back, bad values and wrong board types named;
// Kalibr's target YAML read as a Kalibr-layout grid (and its checkerboard as a chessboard), a bad
// one naming the field and the file.
TEST(BoardSpec, AprilGridLayoutAndKalibrTargetFiles) {
  BoardSpec k = defaultBoard(BoardType::kAprilGrid);
  k.layout = AprilGridLayout::kKalibr;
  k.tag_border_cells = 2;
  nlohmann::json j = boardToJson(k);
  EXPECT_EQ(j.at("layout"), "kalibr");
  EXPECT_EQ(j.at("tag_border_cells"), 2);
  EXPECT_EQ(boardToJson(boardFromJson(j, "k.json")), j);
  for (const auto& [key, bad] : {std::pair<const char*, nlohmann::json>{"layout", "kalibr2"},
                                 {"tag_border_cells", 3}}) {
    nlohmann::json b = j;
    b[key] = bad;
    try {
      boardFromJson(b, "k.json");
      ADD_FAILURE() << "no error for " << key;
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, key) << e.what();
    }
  }
  nlohmann::json c = boardToJson(defaultBoard(BoardType::kCharuco));
  c["layout"] = "kalibr";
  EXPECT_THROW(boardFromJson(c, "c.json"), Error);
  // Kalibr point ids: tag 0 (bottom left of the print) has points 0, 1, 2 cols + 1, 2 cols.
  std::map<int, Eigen::Vector3d> p;
  for (const BoardPoint& bp : boardPoints(k)) p[bp.id] = bp.p_board;
  ASSERT_EQ(p.size(), static_cast<size_t>(4 * k.rows * k.cols));
  EXPECT_EQ(p.rbegin()->first, 4 * k.rows * k.cols - 1);
  const double bottom = k.size_m().y() - k.marker_m;
  EXPECT_NEAR(p[0].y(), bottom, 1e-12);                          // bl of tag 0: bottom edge
  EXPECT_NEAR(p[0].x(), k.marker_m, 1e-12);                      // left
  EXPECT_NEAR(p[1].x() - p[0].x(), k.square_m, 1e-12);           // br to its right
  EXPECT_NEAR(p[0].y() - p[2 * k.cols].y(), k.square_m, 1e-12);  // tl above (y down the print)

  const fs::path dir = test::scratchDir("board", "kalibr");
  const fs::path grid = dir / "aprilgrid.yaml", chess = dir / "checkerboard.yaml", bad = dir / "bad.yaml";
  writeFileAtomic(grid, "target_type: 'aprilgrid' #gridtype\ntagCols: 6   #number of apriltags\ntagRows: 5\n"
                        "tagSize: 0.088           #size of apriltag, edge to edge [m]\ntagSpacing: 0.3\n");
  const BoardSpec g = readBoard(grid);
  EXPECT_EQ(g.type, BoardType::kAprilGrid);
  EXPECT_EQ(g.cols, 6);
  EXPECT_EQ(g.rows, 5);
  EXPECT_DOUBLE_EQ(g.square_m, 0.088);
  EXPECT_NEAR(g.marker_m, 0.0264, 1e-12);
  EXPECT_EQ(g.layout, AprilGridLayout::kKalibr);
  EXPECT_EQ(g.tag_border_cells, 2);
  writeFileAtomic(chess, "target_type: 'checkerboard'\ntargetCols: 8\ntargetRows: 5\nrowSpacingMeters: 0.04\n"
                         "colSpacingMeters: 0.04\n");
  const BoardSpec ch = readBoard(chess);
  EXPECT_EQ(ch.type, BoardType::kChessboard);
  EXPECT_EQ(ch.cols, 9);
  EXPECT_EQ(ch.rows, 6);
  writeFileAtomic(bad, "target_type: 'aprilgrid'\ntagCols: 6\ntagRows: six\ntagSize: 0.088\ntagSpacing: 0.3\n");
  try {
    readBoard(bad);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "tagRows") << e.what();
    EXPECT_EQ(e.context().file, bad.string());
  }
}

TEST(BoardDrawing, ChessboardCornersFoundByOpenCvAtBoardPoints) {
  // 24 px squares; findChessboardCorners + cornerSubPix on the trace, matched to the nearest
  // projected boardPoint. Truth: boardPoints(); tolerance 0.05 px median, 0.1 px max.
  const BoardSpec spec = defaultBoard(BoardType::kChessboard);
  const OrthoView view = viewOf(spec, spec.square_m / 24);
  const cv::Mat image = renderOrtho(spec, someBoardPose(), view);
  std::vector<cv::Point2f> corners;
  ASSERT_TRUE(cv::findChessboardCorners(image, cv::Size(spec.cols - 1, spec.rows - 1), corners,
                                        cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE));
  cv::cornerSubPix(image, corners, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  const auto points = boardPoints(spec);
  ASSERT_EQ(corners.size(), points.size());
  std::vector<double> errors;
  for (const auto& c : corners) {
    double best = 1e9;
    for (const auto& p : points) best = std::min(best, (view.toPixel(p.p_board) - Eigen::Vector2d(c.x, c.y)).norm());
    errors.push_back(best);
  }
  const double max_err = *std::max_element(errors.begin(), errors.end());
  EXPECT_LE(median(errors), 0.05);
  EXPECT_LE(max_err, 0.1);
  // OpenCV orders corners row-major from one end: first and last are board corners 0 and N-1
  // (or the reverse).
  const Eigen::Vector2d first(corners.front().x, corners.front().y);
  const double d0 = (first - view.toPixel(points.front().p_board)).norm();
  const double d1 = (first - view.toPixel(points.back().p_board)).norm();
  EXPECT_LT(std::min(d0, d1), 0.1);
  std::printf("[ chessboard ] %zu corners, median %.4f px, max %.4f px\n", corners.size(), median(errors), max_err);
}

void checkCharuco(const BoardSpec& spec) {
  // ArUco detection + ChArUco interpolation with OpenCV's own board of the same layout must
  // return every inner corner with OpenCV's ids; after a tight cornerSubPix (OpenCV 4.6's
  // interpolation stops refining at 0.1 px steps and leaves ~0.4 px of bias on clean images)
  // the corners lie at boardPoints() (0.05 px median, 0.1 max). 60 px squares: the markers'
  // 7.5 px inset keeps the 11 x 11 refinement window on the chessboard corner alone.
  const OrthoView view = viewOf(spec, spec.square_m / 60);
  const cv::Mat image = renderOrtho(spec, someBoardPose(), view);
  const auto dictionary = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_1000);
  const auto board = cv::aruco::CharucoBoard::create(spec.cols, spec.rows, static_cast<float>(spec.square_m),
                                                     static_cast<float>(spec.marker_m), dictionary);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(image, dictionary, marker_corners, marker_ids);
  EXPECT_EQ(marker_ids.size(), static_cast<size_t>(spec.rows * spec.cols / 2));
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, image, board, corners, ids);
  if (!corners.empty())
    cv::cornerSubPix(image, corners, cv::Size(5, 5), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  const auto points = boardPoints(spec);
  ASSERT_EQ(ids.size(), points.size()) << spec.rows << " rows";
  std::map<int, Eigen::Vector3d> by_id;
  for (const auto& p : points) by_id[p.id] = p.p_board;
  std::vector<double> errors;
  for (size_t i = 0; i < ids.size(); ++i) {
    ASSERT_TRUE(by_id.count(ids[i]));
    errors.push_back((view.toPixel(by_id[ids[i]]) - Eigen::Vector2d(corners[i].x, corners[i].y)).norm());
  }
  const double max_err = *std::max_element(errors.begin(), errors.end());
  EXPECT_LE(median(errors), 0.05);
  EXPECT_LE(max_err, 0.1);
  std::printf("[ charuco %dx%d ] %zu markers, %zu corners with matching ids, median %.4f px, max %.4f px\n",
              spec.rows, spec.cols, marker_ids.size(), ids.size(), median(errors), max_err);
}

TEST(BoardDrawing, CharucoOddRowsDetectedByOpenCvWithBoardPointIds) {
  checkCharuco(defaultBoard(BoardType::kCharuco));
}

TEST(BoardDrawing, CharucoEvenRowsDetectedByOpenCvWithBoardPointIds) {
  BoardSpec spec = defaultBoard(BoardType::kCharuco);
  spec.rows = 6;
  checkCharuco(spec);
}

TEST(BoardDrawing, CharucoLegacyEvenRowsHasWhiteTopLeftAndMarkersInWhiteSquares) {
  // OpenCV 4.6 cannot interpolate this layout, so check it directly: the top-left square is
  // white; every marker OpenCV detects sits in a white square, in row-major order of the white
  // squares; the chessboard corners are where boardPoints() puts them (cornerSubPix started
  // 1.5 px off converges back to <= 0.1 px).
  BoardSpec spec = defaultBoard(BoardType::kCharuco);
  spec.rows = 6;
  spec.legacy_pattern = true;
  const OrthoView view = viewOf(spec, spec.square_m / 60);
  const cv::Mat image = renderOrtho(spec, someBoardPose(), view);
  const Eigen::Vector2d tl = view.toPixel(Eigen::Vector3d(0.1 * spec.square_m, 0.1 * spec.square_m, 0));
  EXPECT_GT(image.at<std::uint8_t>(static_cast<int>(tl.y()), static_cast<int>(tl.x())), 120);
  const auto dictionary = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_1000);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(image, dictionary, marker_corners, marker_ids);
  ASSERT_EQ(marker_ids.size(), static_cast<size_t>(spec.rows * spec.cols / 2));
  std::vector<int> white_squares;  // row-major index of each white square
  for (int r = 0; r < spec.rows; ++r)
    for (int c = 0; c < spec.cols; ++c)
      if ((r + c) % 2 == 0) white_squares.push_back(r * spec.cols + c);  // legacy, even rows
  for (size_t i = 0; i < marker_ids.size(); ++i) {
    cv::Point2f centre(0, 0);
    for (const auto& p : marker_corners[i]) centre += 0.25f * p;
    const double x = view.x0 + centre.x * view.px, y = view.y0 + centre.y * view.px;
    const int square = static_cast<int>(y / spec.square_m) * spec.cols + static_cast<int>(x / spec.square_m);
    ASSERT_LT(marker_ids[i], static_cast<int>(white_squares.size()));
    EXPECT_EQ(square, white_squares[marker_ids[i]]) << "marker " << marker_ids[i];
  }
  std::vector<cv::Point2f> corners;
  for (const auto& p : boardPoints(spec)) {
    const Eigen::Vector2d px = view.toPixel(p.p_board);
    corners.emplace_back(static_cast<float>(px.x() + 1.5), static_cast<float>(px.y() - 1.5));
  }
  cv::cornerSubPix(image, corners, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  double max_err = 0;
  const auto points = boardPoints(spec);
  for (size_t i = 0; i < corners.size(); ++i)
    max_err = std::max(max_err, (view.toPixel(points[i].p_board) - Eigen::Vector2d(corners[i].x, corners[i].y)).norm());
  EXPECT_LE(max_err, 0.1);
  std::printf("[ charuco legacy 6x10 ] %zu markers in the legacy squares, corners max %.4f px\n",
              marker_ids.size(), max_err);
}

TEST(BoardDrawing, AprilGridTagsDecodedByLibapriltagAtBoardPoints) {
  // Kalibr layout with libapriltag's tag36h11: each detection's id - first_id is the tag index
  // and its corners p[0..3] (bl, br, tr, tl) are boardPoints 4 * index + k. libapriltag's pixel
  // origin is the image's top-left corner: subtract 0.5. 10 px per tag cell.
  BoardSpec spec = defaultBoard(BoardType::kAprilGrid);
  spec.first_id = 7;
  const OrthoView view = viewOf(spec, spec.square_m / 8 / 10);
  const cv::Mat image = renderOrtho(spec, someBoardPose(), view);
  image_u8_t* im = image_u8_create(image.cols, image.rows);
  for (int v = 0; v < image.rows; ++v)
    std::memcpy(im->buf + v * im->stride, image.ptr(v), static_cast<size_t>(image.cols));
  apriltag_family_t* family = tag36h11_create();
  apriltag_detector_t* detector = apriltag_detector_create();
  apriltag_detector_add_family(detector, family);
  detector->quad_decimate = 1;
  detector->nthreads = 1;
  zarray_t* detections = apriltag_detector_detect(detector, im);
  const auto points = boardPoints(spec);
  std::vector<double> errors;
  std::vector<bool> seen(static_cast<size_t>(spec.rows * spec.cols), false);
  for (int i = 0; i < zarray_size(detections); ++i) {
    apriltag_detection_t* det;
    zarray_get(detections, i, &det);
    const int index = det->id - spec.first_id;
    ASSERT_GE(index, 0);
    ASSERT_LT(index, spec.rows * spec.cols);
    seen[index] = true;
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d expected = view.toPixel(points[4 * index + k].p_board);
      errors.push_back((Eigen::Vector2d(det->p[k][0] - 0.5, det->p[k][1] - 0.5) - expected).norm());
    }
  }
  const int found = static_cast<int>(std::count(seen.begin(), seen.end(), true));
  apriltag_detections_destroy(detections);
  apriltag_detector_destroy(detector);
  tag36h11_destroy(family);
  image_u8_destroy(im);
  // libapriltag sometimes misses a tag whose corners touch Kalibr's squares; most must decode.
  EXPECT_GE(found, spec.rows * spec.cols * 3 / 4);
  ASSERT_FALSE(errors.empty());
  const double max_err = *std::max_element(errors.begin(), errors.end());
  // libapriltag itself places corners of ideal tags up to ~0.4 px inwards on the bottom/right
  // edges (measured here; the texture is exact: the chessboard/ChArUco tests reach 0.03 px).
  EXPECT_LE(median(errors), 0.3);
  EXPECT_LE(max_err, 0.6);
  std::printf("[ aprilgrid ] %d/%d tags decoded, corner error median %.3f px, max %.3f px (tag = 80 px)\n",
              found, spec.rows * spec.cols, median(errors), max_err);
}

TEST(BoardDrawing, CirclesRingsCentredAtBoardPoints) {
  // Truth: boardPoints() (circle centres). The darkness-weighted centroid over a disc that
  // holds one whole target and only white around it is the target's centre; rings are black
  // at r < R/3, white in (R/3, 2R/3), black in (2R/3, R), white beyond.
  const BoardSpec spec = defaultBoard(BoardType::kCircles);
  const OrthoView view = viewOf(spec, spec.circle_radius_m / 30);
  const cv::Mat image = renderOrtho(spec, someBoardPose(), view);
  const double R = spec.circle_radius_m / view.px;
  const double window = 0.5 * (spec.circle_radius_m + 0.5 * spec.square_m) / view.px;
  std::vector<double> errors;
  for (const auto& p : boardPoints(spec)) {
    const Eigen::Vector2d c = view.toPixel(p.p_board);
    double sw = 0, sx = 0, sy = 0;
    for (int v = static_cast<int>(c.y() - window) - 1; v <= static_cast<int>(c.y() + window) + 1; ++v)
      for (int u = static_cast<int>(c.x() - window) - 1; u <= static_cast<int>(c.x() + window) + 1; ++u) {
        if (std::hypot(u - c.x(), v - c.y()) > window) continue;
        const double w = 255.0 - image.at<std::uint8_t>(v, u);
        sw += w;
        sx += w * u;
        sy += w * v;
      }
    errors.push_back((Eigen::Vector2d(sx / sw, sy / sw) - c).norm());
    auto at = [&](double r) {
      return image.at<std::uint8_t>(static_cast<int>(std::lround(c.y())), static_cast<int>(std::lround(c.x() + r)));
    };
    EXPECT_LT(at(0.15 * R), 60);
    EXPECT_GT(at(0.5 * R), 120);  // the board's white under this pose's light is ~160
    EXPECT_LT(at(0.83 * R), 60);
    EXPECT_GT(at(1.2 * R), 120);
  }
  const double max_err = *std::max_element(errors.begin(), errors.end());
  EXPECT_LE(max_err, 0.05);
  std::printf("[ circles ] %zu centres, centroid error max %.4f px (R = %.0f px)\n", errors.size(), max_err, R);
}

TEST(BoardDrawing, QuadtreeMarkersDecodedByOpenCvAtBoardPoints) {
  // OpenCV's ArUco detector on an orthographic render (1.2 mm pixels: the centre cell's 24 mm
  // markers are 20 px, 3.3 px a bit): every marker decodes with id first_id + index, its
  // corners in OpenCV's order at boardPoints 4 * index + k (OpenCV's unrefined corners, the
  // thresholded contour's polygon, sit up to a pixel inside the marker; a corner out of order
  // would be a marker edge, 20 px or more, off).
  BoardSpec spec = defaultBoard(BoardType::kQuadtree);
  spec.first_id = 11;
  const OrthoView view = viewOf(spec, 0.0012);
  const cv::Mat image = renderOrtho(spec, someBoardPose(), view);
  const auto dictionary = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_250);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(image, dictionary, marker_corners, marker_ids);
  const auto points = boardPoints(spec);
  const auto markers = quadtreeMarkers(spec);
  std::vector<bool> seen(markers.size(), false);
  std::vector<double> corner_errors;
  for (size_t i = 0; i < marker_ids.size(); ++i) {
    const int index = marker_ids[i] - spec.first_id;
    ASSERT_GE(index, 0);
    ASSERT_LT(index, static_cast<int>(markers.size()));
    seen[index] = true;
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d expected = view.toPixel(points[4 * index + k].p_board);
      const Eigen::Vector2d got(marker_corners[i][k].x, marker_corners[i][k].y);
      corner_errors.push_back((got - expected).norm());
    }
  }
  // The drawing itself: every marker's top edge at its middle column and left edge at its
  // middle row, from the white fraction of the pixel the edge crosses (linear light, levels
  // from the paper 2 px outside and the border bit's middle 0.5 bit inside): where
  // quadtreeMarkers() puts them, to the render's coverage quantisation (1/16 px) and rounding.
  auto lin = [&](double u, double v) {
    const double x = image.at<std::uint8_t>(static_cast<int>(std::lround(v)), static_cast<int>(std::lround(u))) / 255.0;
    return x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4);
  };
  std::vector<double> edge_errors;
  for (const QuadtreeMarker& m : markers) {
    const double bit_px = m.edge_m / 6 / view.px;
    for (int side = 0; side < 2; ++side) {
      // side 0: top edge, crossing along v at the middle column; side 1: left edge along u.
      const Eigen::Vector3d at_board = side == 0
          ? Eigen::Vector3d(m.top_left.x() + 0.5 * m.edge_m, m.top_left.y(), 0)
          : Eigen::Vector3d(m.top_left.x(), m.top_left.y() + 0.5 * m.edge_m, 0);
      const Eigen::Vector2d at = view.toPixel(at_board);
      const double truth = side == 0 ? at.y() : at.x();
      const double crossed = std::round(truth);
      auto sample = [&](double d) { return side == 0 ? lin(at.x(), d) : lin(d, at.y()); };
      const double white = sample(crossed - 2), black = sample(truth + 0.5 * bit_px);
      const double f = (sample(crossed) - black) / (white - black);
      edge_errors.push_back(std::abs(crossed - 0.5 + f - truth));
    }
  }
  const double max_edge = *std::max_element(edge_errors.begin(), edge_errors.end());
  EXPECT_LE(max_edge, 0.08);
  EXPECT_EQ(std::count(seen.begin(), seen.end(), true), static_cast<long>(markers.size()));
  ASSERT_FALSE(corner_errors.empty());
  const double max_corner = *std::max_element(corner_errors.begin(), corner_errors.end());
  EXPECT_LE(max_corner, 1.5);
  std::printf("[ quadtree ] %zu/%zu markers decoded, OpenCV's corners median %.3f px max %.3f "
              "px; drawn edges max %.4f px from the layout\n",
              marker_ids.size(), markers.size(), median(corner_errors), max_corner, max_edge);
}

TEST(BoardDrawing, BackIsPlainAndHitsAreBoardClass) {
  const BoardSpec spec = defaultBoard(BoardType::kChessboard);
  const Pose T = someBoardPose();
  Scene scene;
  scene.add(makeBoard(spec, T));
  const Eigen::Vector3d z = T.linear().col(2);
  Hit front, back;
  // Through a black square (top-left) from the front, and from behind.
  const Eigen::Vector3d p = T * Eigen::Vector3d(0.5 * spec.square_m, 0.5 * spec.square_m, 0);
  ASSERT_TRUE(scene.trace(Ray{p - z, z}, front));
  ASSERT_TRUE(scene.trace(Ray{p + z, -z}, back));
  EXPECT_EQ(front.cls, ObjectClass::kBoard);
  EXPECT_EQ(back.cls, ObjectClass::kBoard);
  EXPECT_NEAR(front.t, 1.0, 1e-12);
  EXPECT_LT(front.normal.dot(z), 0);
  EXPECT_GT(back.normal.dot(z), 0);
  EXPECT_LT(front.rgb.maxCoeff(), 0.1f);  // black square
  EXPECT_GT(back.rgb.minCoeff(), 0.1f);   // plain grey back
  // Outside the margin: no hit.
  Hit none;
  EXPECT_FALSE(scene.trace(Ray{T * Eigen::Vector3d(-spec.margin_m - 0.001, 0.1, -1), z}, none));
}

}  // namespace
}  // namespace previz::synth
