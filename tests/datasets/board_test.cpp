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

TEST(BoardSpec, JsonRoundTripAndFileRoundTrip) {
  for (BoardType type : {BoardType::kChessboard, BoardType::kCharuco, BoardType::kAprilGrid, BoardType::kCircles}) {
    BoardSpec spec = defaultBoard(type);
    spec.first_id = type == BoardType::kCharuco ? 100 : 0;
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
  j["type"] = "quadtree";
  try {
    boardFromJson(j, "b.json");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "type");
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
