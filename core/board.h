#pragma once
// Calibration board descriptions shared by the synthetic studio (which draws them) and calib
// (which detects them). The board frame: origin at the top-left outer corner of the printed
// pattern, x along the columns, y along the rows (down the print), z = x × y (into the board,
// away from a viewer who reads the print). Points lie at z = 0. Metres.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

namespace previz {

enum class BoardType { kChessboard, kCharuco, kAprilGrid, kCircles, kQuadtree };
const char* toString(BoardType type);

// Whose numbering an AprilGrid's tags and points follow (boardPoints below):
//  kPreviz: tag index row-major from the top-left of the print (previz's own print, before
//           Kalibr's was supported); point id = 4 * tag index + corner.
//  kKalibr: Kalibr's AprilGrid as Kalibr prints and detects it: tag index row-major from the
//           bottom-left, rows rising up the print; point ids on the grid of 2 x 2 corners per tag,
//           row-major from the bottom-left, 2 cols points a row (tag (row from the bottom rb,
//           col c): bl = 2 rb * 2 cols + 2 c, br = bl + 1, tl = bl + 2 cols, tr = tl + 1).
enum class AprilGridLayout { kPreviz, kKalibr };
const char* toString(AprilGridLayout layout);

struct BoardSpec {
  BoardType type = BoardType::kChessboard;
  int rows = 7;                 // squares (chessboard, ChArUco), tags (AprilGrid), circles,
  int cols = 10;                // outer cells (quadtree: rows == cols)
  double square_m = 0.04;       // chessboard/ChArUco square; AprilGrid tag edge; circle pitch;
                                // quadtree outer cell
  double marker_m = 0.03;       // ChArUco marker edge; AprilGrid: spacing = marker_m (gap);
                                // quadtree: marker edge in an outer cell (smaller cells scale it)
  double circle_radius_m = 0.0; // concentric circles: outer radius (rings at 1, 2/3, 1/3)
  std::string dictionary = "DICT_5X5_1000";  // ChArUco (OpenCV name) or "tag36h11"
  int first_id = 0;             // first marker / tag id
  bool legacy_pattern = false;  // ChArUco: OpenCV < 4.6 layout for even row counts
  double margin_m = 0.01;       // white border around the pattern when printed
  int levels = 3;               // quadtree only: cell sizes (1 = a plain grid of markers)
  // AprilGrid only: the numbering, and the tags' black border in cells (libapriltag's tag36h11
  // has 1; Kalibr prints 2, the code bits the same).
  AprilGridLayout layout = AprilGridLayout::kPreviz;
  int tag_border_cells = 1;

  void validate() const;        // throws Error naming the bad field
  // Extent of the pattern (without margin), metres: (width along x, height along y).
  Eigen::Vector2d size_m() const;
};

// A detectable point of the board: the id a detector reports and its board-frame position.
//  chessboard: inner corners, row-major, id = r * (cols - 1) + c (OpenCV's order)
//  ChArUco:    inner chessboard corners, OpenCV's charuco ids (row-major)
//  AprilGrid:  4 corners per tag (corner 0..3: bl, br, tr, tl as seen in the print, which is
//              libapriltag's order), ids as BoardSpec::layout says (aprilGridPointId)
//  circles:    circle centres, row-major
//  quadtree:   4 corners per marker, id = 4 * marker_index + corner (OpenCV's aruco order: tl,
//              tr, br, bl as seen in the print), marker_index as quadtreeMarkers() lists them
struct BoardPoint {
  int id;
  Eigen::Vector3d p_board;
};
std::vector<BoardPoint> boardPoints(const BoardSpec& spec);

// AprilGrid: where tag index k (= tag id - first_id) is printed (row 0 at the top of the print),
// the index printed at (row, col), and the point id of its corner (0..3: bl, br, tr, tl).
struct GridCell {
  int row = 0, col = 0;
};
GridCell aprilGridTagCell(const BoardSpec& spec, int tag_index);
int aprilGridTagIndex(const BoardSpec& spec, int row, int col);
int aprilGridPointId(const BoardSpec& spec, int tag_index, int corner);

// The quadtree ArUco board (the thesis' design): a square of cols x cols outer cells of
// square_m (rows == cols). Cell (r, c) lies in ring k = min(r, c, cols-1-r, cols-1-c) (its
// Chebyshev distance from the board's edge: the outer ring is k = 0, the centre has the
// largest k) and has level L = min(k, levels - 1): it is split into 2^L x 2^L sub-cells of
// square_m / 2^L, and every (sub-)cell holds one marker of the dictionary, of edge
// marker_m / 2^L, centred in it. Markers thus shrink towards the centre: whatever the
// distance, some markers have a usable size in the image, and near a close camera's centre
// many small ones give dense points. Marker order (id = first_id + index): outer cells
// row-major, within a cell its sub-cells row-major. Markers are drawn as OpenCV draws them (a
// one-bit black border around the code), so a marker's corners are L-shaped black corners on
// white paper.
struct QuadtreeMarker {
  Eigen::Vector2d top_left;  // board frame, metres
  double edge_m = 0;         // marker edge
  double cell_m = 0;         // the (sub-)cell it is centred in
  int level = 0;
};
int quadtreeLevel(const BoardSpec& spec, int r, int c);
std::vector<QuadtreeMarker> quadtreeMarkers(const BoardSpec& spec);  // index = marker order

// OpenCV's PREDEFINED_DICTIONARY_NAME value for a dictionary name ("DICT_5X5_1000", ...), for
// cv::aruco::getPredefinedDictionary. Throws Error naming the field 'dictionary' when unknown.
int openCvDictionaryId(const std::string& name);

nlohmann::json boardToJson(const BoardSpec& spec);
BoardSpec boardFromJson(const nlohmann::json& j, const std::string& file = {});
// A board file: previz's JSON, or Kalibr's target YAML (target_type 'aprilgrid' with tagCols,
// tagRows, tagSize, tagSpacing: a Kalibr-layout AprilGrid with 2-cell tag borders; or
// 'checkerboard' with targetCols, targetRows (inner corners), rowSpacingMeters = colSpacingMeters).
BoardSpec readBoard(const std::filesystem::path& path);
void writeBoard(const BoardSpec& spec, const std::filesystem::path& path);  // atomic

}  // namespace previz
