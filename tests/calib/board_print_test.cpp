// Printable boards: physical size of the PNG at its DPI, the DPI stored in the PNG, the SVG in
// millimetres, the JSON beside them, and every board point found again in the printed PNG where
// the board geometry puts it.
#include "calib/board_print.h"

#include <cmath>
#include <map>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calib/detect.h"
#include "core/error.h"
#include "core/io.h"
#include "scratch.h"

namespace previz::calib {
namespace {

namespace fs = std::filesystem;

std::string readBytes(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// pHYs of a PNG: pixels per unit x, y and the unit (1 = metre); false when absent.
bool readPhys(const std::string& png, std::uint32_t& ppm_x, std::uint32_t& ppm_y, int& unit) {
  const size_t at = png.find("pHYs");
  if (at == std::string::npos || at + 13 > png.size()) return false;
  auto be = [&](size_t k) {
    return (std::uint32_t(std::uint8_t(png[k])) << 24) |
           (std::uint32_t(std::uint8_t(png[k + 1])) << 16) |
           (std::uint32_t(std::uint8_t(png[k + 2])) << 8) | std::uint32_t(std::uint8_t(png[k + 3]));
  };
  ppm_x = be(at + 4);
  ppm_y = be(at + 8);
  unit = std::uint8_t(png[at + 12]);
  return true;
}

std::vector<BoardSpec> smallBoards() {
  std::vector<BoardSpec> boards;
  BoardSpec chess;
  chess.type = BoardType::kChessboard;
  chess.rows = 5;
  chess.cols = 8;
  chess.square_m = 0.02;
  chess.margin_m = 0.015;
  boards.push_back(chess);
  BoardSpec charuco;
  charuco.type = BoardType::kCharuco;
  charuco.rows = 5;
  charuco.cols = 7;
  charuco.square_m = 0.03;
  charuco.marker_m = 0.022;
  charuco.dictionary = "DICT_4X4_50";
  charuco.first_id = 3;
  charuco.margin_m = 0.01;
  boards.push_back(charuco);
  BoardSpec legacy = charuco;
  legacy.rows = 4;
  legacy.legacy_pattern = true;
  boards.push_back(legacy);
  BoardSpec grid;
  grid.type = BoardType::kAprilGrid;
  grid.rows = 3;
  grid.cols = 4;
  grid.square_m = 0.03;
  grid.marker_m = 0.009;
  grid.dictionary = "tag36h11";
  grid.first_id = 5;
  grid.margin_m = 0.01;
  boards.push_back(grid);
  BoardSpec kalibr = grid;  // Kalibr's print: numbered from the bottom left, 2-cell tag borders
  kalibr.layout = AprilGridLayout::kKalibr;
  kalibr.tag_border_cells = 2;
  kalibr.first_id = 0;
  boards.push_back(kalibr);
  BoardSpec circles;
  circles.type = BoardType::kCircles;
  circles.rows = 4;
  circles.cols = 5;
  circles.square_m = 0.03;
  circles.circle_radius_m = 0.011;
  circles.margin_m = 0.01;
  boards.push_back(circles);
  BoardSpec quad;
  quad.type = BoardType::kQuadtree;
  quad.rows = quad.cols = 3;
  quad.levels = 2;  // 8 outer markers of 48 mm, the centre cell's 2 x 2 of 24 mm
  quad.square_m = 0.06;
  quad.marker_m = 0.048;
  quad.dictionary = "DICT_4X4_50";
  quad.first_id = 2;
  quad.margin_m = 0.01;
  boards.push_back(quad);
  return boards;
}

TEST(BoardPrint, PngHasPhysicalSizeAndDpiAndEveryPointIsRedetected) {
  const fs::path dir = test::scratchDir("board_print", "boards");
  const double dpi = 100;
  int n = 0;
  for (const BoardSpec& spec : smallBoards()) {
    const fs::path stem = dir / (std::string(toString(spec.type)) + "_" + std::to_string(n++));
    const PrintedBoard printed = printBoard(spec, dpi, stem);
    ASSERT_TRUE(fs::exists(printed.png));
    ASSERT_TRUE(fs::exists(printed.svg));
    ASSERT_TRUE(fs::exists(printed.json));

    // Size: sheet (pattern + 2 margins) x DPI / 25.4 mm, to +-1 px.
    const Eigen::Vector2d sheet_mm =
        (spec.size_m() + Eigen::Vector2d::Constant(2 * spec.margin_m)) * 1000;
    const cv::Mat png = cv::imread(printed.png.string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(png.empty());
    EXPECT_EQ(png.type(), CV_8UC1);
    EXPECT_NEAR(png.cols, sheet_mm.x() * dpi / 25.4, 1.0);
    EXPECT_NEAR(png.rows, sheet_mm.y() * dpi / 25.4, 1.0);
    EXPECT_NEAR(printed.width_mm, sheet_mm.x(), 1e-9);

    std::uint32_t ppm_x = 0, ppm_y = 0;
    int unit = 0;
    ASSERT_TRUE(readPhys(readBytes(printed.png), ppm_x, ppm_y, unit))
        << "no pHYs in " << printed.png;
    EXPECT_EQ(unit, 1);
    EXPECT_EQ(ppm_x, static_cast<std::uint32_t>(std::lround(dpi / 0.0254)));
    EXPECT_EQ(ppm_y, ppm_x);

    const std::string svg = readBytes(printed.svg);
    char size_attr[96];
    std::snprintf(size_attr, sizeof size_attr, "width=\"%gmm\" height=\"%gmm\"",
                  std::round(sheet_mm.x() * 1e4) / 1e4, std::round(sheet_mm.y() * 1e4) / 1e4);
    EXPECT_NE(svg.find(size_attr), std::string::npos) << size_attr << " not in " << printed.svg;
    EXPECT_EQ(readBoard(printed.json).rows, spec.rows);
    EXPECT_EQ(boardToJson(readBoard(printed.json)), boardToJson(spec));

    // Every point found again, where the geometry puts it: board (x, y) -> pixel
    // ((x + margin) px_per_m - 0.5, ...). Edges of the binary print lie on pixel boundaries,
    // up to half a pixel from the exact ones, so a point may be off by sqrt(2)/2 px.
    const double px_per_m = dpi / 0.0254;
    const ViewObservations obs = detectBoard(png, spec, {}, printed.png.string());
    std::map<int, Eigen::Vector3d> points;
    for (const BoardPoint& bp : boardPoints(spec)) points[bp.id] = bp.p_board;
    EXPECT_EQ(obs.points.size(), points.size()) << toString(spec.type) << ": " << obs.failure;
    double worst = 0;
    for (const Observation& o : obs.points) {
      ASSERT_EQ(points.count(o.id), 1u) << o.id;
      const Eigen::Vector3d& p = points.at(o.id);
      const Eigen::Vector2d expected((p.x() + spec.margin_m) * px_per_m - 0.5,
                                     (p.y() + spec.margin_m) * px_per_m - 0.5);
      worst = std::max(worst, (expected - o.px).norm());
    }
    std::printf("%s%s: %d x %d px, %zu of %zu points, max %.3f px from the geometry\n",
                toString(spec.type), spec.legacy_pattern ? " (legacy)" : "", png.cols, png.rows,
                obs.points.size(), points.size(), worst);
    EXPECT_LE(worst, 0.71) << toString(spec.type);
  }
}

// A Kalibr-layout AprilGrid prints as Kalibr prints it: tag 0 at the bottom left of the sheet
// with ids rising to the right and then up, 2-cell black borders (libapriltag's own tag36h11
// family, 1-cell, decodes none of it), and Kalibr's aprilgrid.yaml beside it, which reads back
// as the same board.
TEST(BoardPrint, KalibrLayoutAprilGridIsKalibrsPrint) {
  BoardSpec spec;
  spec.type = BoardType::kAprilGrid;
  spec.rows = 3;
  spec.cols = 4;
  spec.square_m = 0.03;
  spec.marker_m = 0.009;
  spec.dictionary = "tag36h11";
  spec.margin_m = 0.01;
  spec.layout = AprilGridLayout::kKalibr;
  spec.tag_border_cells = 2;
  const fs::path stem = test::scratchDir("board_print", "kalibr") / "aprilgrid";
  const PrintedBoard printed = printBoard(spec, 150, stem);
  ASSERT_TRUE(fs::exists(printed.kalibr_yaml));
  const std::string yaml = readBytes(printed.kalibr_yaml);
  EXPECT_NE(yaml.find("target_type: 'aprilgrid'"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("tagSpacing: 0.3"), std::string::npos) << yaml;
  EXPECT_EQ(boardToJson(readBoard(printed.kalibr_yaml)), boardToJson(spec));
  const cv::Mat png = cv::imread(printed.png.string(), cv::IMREAD_GRAYSCALE);
  const ViewObservations obs = detectBoard(png, spec, {}, "kalibr print");
  ASSERT_EQ(obs.tags.size(), 12u) << obs.failure;
  std::map<int, Eigen::Vector2d> px;
  for (const Observation& o : obs.points) px[o.id] = o.px;
  // Kalibr's point ids: tag 0's bl corner is point 0, at the bottom left of the sheet; point 1 (its
  // br) to the right; point 2 cols (its tl) above; tag 1's bl (point 2) further right.
  ASSERT_EQ(px.size(), 48u);
  EXPECT_LT(px.at(0).x(), 0.15 * png.cols);
  EXPECT_GT(px.at(0).y(), 0.85 * png.rows);
  EXPECT_GT(px.at(1).x(), px.at(0).x() + 20);
  EXPECT_LT(px.at(8).y(), px.at(0).y() - 20);
  EXPECT_NEAR(px.at(8).x(), px.at(0).x(), 1.0);
  EXPECT_GT(px.at(2).x(), px.at(1).x());
  for (const DecodedTag& tag : obs.tags) EXPECT_EQ(tag.bit_errors, 0);
  // The same print read as a 1-cell-border board: nothing decodes.
  BoardSpec one = spec;
  one.tag_border_cells = 1;
  EXPECT_FALSE(detectBoard(png, one, {}, "kalibr print as border 1").found());
}

TEST(BoardPrint, DrawBoardPutsPointsAtTheirPhysicalPlace) {
  // At 1 px per mm a 10 mm chessboard square covers exactly 10 pixels: the first inner corner
  // (board (10, 10) mm, margin 5 mm) lies between pixels 14 and 15.
  BoardSpec spec;
  spec.type = BoardType::kChessboard;
  spec.rows = 3;
  spec.cols = 4;
  spec.square_m = 0.01;
  spec.margin_m = 0.005;
  const cv::Mat img = drawBoard(spec, 1000.0);
  ASSERT_EQ(img.cols, 50);
  ASSERT_EQ(img.rows, 40);
  EXPECT_EQ(img.at<std::uint8_t>(4, 4), 255);  // margin
  EXPECT_EQ(img.at<std::uint8_t>(5, 5), 0);    // first (black) square
  EXPECT_EQ(img.at<std::uint8_t>(14, 14), 0);
  EXPECT_EQ(img.at<std::uint8_t>(14, 15), 255);  // next square, white
  EXPECT_EQ(img.at<std::uint8_t>(15, 15), 0);
}

TEST(BoardPrint, BadDpiAndBoardThrowNamingTheField) {
  BoardSpec spec;
  try {
    printBoard(spec, 0, test::scratchDir("board_print", "bad") / "board");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("dpi"), std::string::npos) << e.what();
  }
  spec.rows = 1;
  try {
    printBoard(spec, 100, test::scratchDir("board_print", "bad") / "board");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("rows"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace previz::calib
