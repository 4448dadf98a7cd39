#include "core/board.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/detail/yaml_subset.h"

namespace previz {

namespace {

// Marker grid size (bits, without the black border) and code count of the dictionaries a
// board may name. Kept here rather than asked of OpenCV so that core validates boards without
// the aruco module; the values are OpenCV's predefined dictionaries (aruco/dictionary.hpp),
// listed in the order of OpenCV's PREDEFINED_DICTIONARY_NAME enum (index = OpenCV's id).
struct DictionaryInfo {
  const char* name;
  int marker_bits;
  int size;
};
constexpr DictionaryInfo kDictionaries[] = {
    {"DICT_4X4_50", 4, 50},          {"DICT_4X4_100", 4, 100},
    {"DICT_4X4_250", 4, 250},        {"DICT_4X4_1000", 4, 1000},
    {"DICT_5X5_50", 5, 50},          {"DICT_5X5_100", 5, 100},
    {"DICT_5X5_250", 5, 250},        {"DICT_5X5_1000", 5, 1000},
    {"DICT_6X6_50", 6, 50},          {"DICT_6X6_100", 6, 100},
    {"DICT_6X6_250", 6, 250},        {"DICT_6X6_1000", 6, 1000},
    {"DICT_7X7_50", 7, 50},          {"DICT_7X7_100", 7, 100},
    {"DICT_7X7_250", 7, 250},        {"DICT_7X7_1000", 7, 1000},
    {"DICT_ARUCO_ORIGINAL", 5, 1024}, {"DICT_APRILTAG_16h5", 4, 30},
    {"DICT_APRILTAG_25h9", 5, 35},   {"DICT_APRILTAG_36h10", 6, 2320},
    {"DICT_APRILTAG_36h11", 6, 587},
};
constexpr int kTag36h11Codes = 587;  // libapriltag's tag36h11 family

const DictionaryInfo* findDictionary(const std::string& name) {
  for (const auto& d : kDictionaries)
    if (name == d.name) return &d;
  return nullptr;
}

}  // namespace

int openCvDictionaryId(const std::string& name) {
  const DictionaryInfo* d = findDictionary(name);
  if (!d) {
    ErrorContext context;
    context.field = "dictionary";
    throw Error("board: dictionary '" + name + "' is not an OpenCV predefined dictionary", context);
  }
  return static_cast<int>(d - kDictionaries);
}

namespace {

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

[[noreturn]] void fail(const std::string& field, const std::string& what) {
  ErrorContext context;
  context.field = field;
  throw Error("board: " + field + " " + what, context);
}

void requirePositive(const std::string& field, double v) {
  if (!(std::isfinite(v) && v > 0)) fail(field, "must be a finite number > 0 (got " + num(v) + ")");
}

BoardType boardTypeFromString(const std::string& s, const std::string& file) {
  if (s == "chessboard") return BoardType::kChessboard;
  if (s == "charuco") return BoardType::kCharuco;
  if (s == "aprilgrid") return BoardType::kAprilGrid;
  if (s == "circles") return BoardType::kCircles;
  if (s == "quadtree") return BoardType::kQuadtree;
  ErrorContext context;
  context.file = file;
  context.field = "type";
  throw Error("board: unknown type '" + s + "' (expected chessboard|charuco|aprilgrid|circles|quadtree)",
              context);
}

}  // namespace

const char* toString(BoardType type) {
  switch (type) {
    case BoardType::kChessboard: return "chessboard";
    case BoardType::kCharuco: return "charuco";
    case BoardType::kAprilGrid: return "aprilgrid";
    case BoardType::kCircles: return "circles";
    case BoardType::kQuadtree: return "quadtree";
  }
  return "unknown";
}

void BoardSpec::validate() const {
  // Chessboards need at least 2 x 2 inner corners for OpenCV's detector; the others at least
  // one cell. 200 is far beyond any printable board and keeps ids within int.
  const int min_cells = type == BoardType::kChessboard ? 3
                        : type == BoardType::kCharuco  ? 2
                                                       : 1;
  if (rows < min_cells || rows > 200)
    fail("rows", "must be in [" + std::to_string(min_cells) + ", 200] for a " +
                     toString(type) + " (got " + std::to_string(rows) + ")");
  if (cols < min_cells || cols > 200)
    fail("cols", "must be in [" + std::to_string(min_cells) + ", 200] for a " +
                     toString(type) + " (got " + std::to_string(cols) + ")");
  requirePositive("square_m", square_m);
  if (!(std::isfinite(margin_m) && margin_m >= 0))
    fail("margin_m", "must be a finite number >= 0 (got " + num(margin_m) + ")");
  if (first_id < 0) fail("first_id", "must be >= 0 (got " + std::to_string(first_id) + ")");
  if (legacy_pattern && type != BoardType::kCharuco)
    fail("legacy_pattern", "applies to charuco boards only (this board is a " +
                               std::string(toString(type)) + ")");

  switch (type) {
    case BoardType::kChessboard: break;
    case BoardType::kCharuco: {
      requirePositive("marker_m", marker_m);
      if (marker_m >= square_m)
        fail("marker_m", "must be smaller than square_m (" + num(square_m) + ") (got " +
                             num(marker_m) + ")");
      const DictionaryInfo* d = findDictionary(dictionary);
      if (!d) fail("dictionary", "'" + dictionary + "' is not an OpenCV predefined dictionary");
      const int markers = rows * cols / 2;  // one per white square
      if (first_id + markers > d->size)
        fail("first_id", "+ " + std::to_string(markers) + " markers exceeds the " +
                             std::to_string(d->size) + " codes of " + dictionary);
      break;
    }
    case BoardType::kAprilGrid: {
      requirePositive("marker_m", marker_m);  // the gap between tags
      if (dictionary != "tag36h11")
        fail("dictionary", "must be 'tag36h11' for an aprilgrid (got '" + dictionary + "')");
      if (first_id + rows * cols > kTag36h11Codes)
        fail("first_id", "+ " + std::to_string(rows * cols) + " tags exceeds the " +
                             std::to_string(kTag36h11Codes) + " codes of tag36h11");
      if (tag_border_cells < 1 || tag_border_cells > 2)
        fail("tag_border_cells", "must be 1 (libapriltag's tag36h11) or 2 (Kalibr's print) (got " +
                                     std::to_string(tag_border_cells) + ")");
      break;
    }
    case BoardType::kCircles: {
      requirePositive("circle_radius_m", circle_radius_m);
      if (2 * circle_radius_m >= square_m)
        fail("circle_radius_m", "must be below half the pitch square_m (" + num(square_m) +
                                    ") so circles do not touch (got " + num(circle_radius_m) +
                                    ")");
      break;
    }
    case BoardType::kQuadtree: {
      if (rows != cols)
        fail("rows", "must equal cols for a quadtree board (got " + std::to_string(rows) + " x " +
                         std::to_string(cols) + ")");
      if (levels < 1 || levels > 6)
        fail("levels", "must be in [1, 6] (got " + std::to_string(levels) + ")");
      requirePositive("marker_m", marker_m);
      if (marker_m >= square_m)
        fail("marker_m", "must be smaller than square_m (" + num(square_m) + ") (got " +
                             num(marker_m) + ")");
      const DictionaryInfo* d = findDictionary(dictionary);
      if (!d) fail("dictionary", "'" + dictionary + "' is not an OpenCV predefined dictionary");
      long long markers = 0;
      for (int r = 0; r < rows; ++r)
        for (int c = 0; c < cols; ++c) markers += 1LL << (2 * quadtreeLevel(*this, r, c));
      if (first_id + markers > d->size)
        fail("first_id", "+ " + std::to_string(markers) + " markers exceeds the " +
                             std::to_string(d->size) + " codes of " + dictionary +
                             " (fewer levels or cols, or a _1000 dictionary)");
      break;
    }
  }
}

int quadtreeLevel(const BoardSpec& spec, int r, int c) {
  const int ring = std::min(std::min(r, c), std::min(spec.cols - 1 - r, spec.cols - 1 - c));
  return std::max(0, std::min(ring, spec.levels - 1));
}

std::vector<QuadtreeMarker> quadtreeMarkers(const BoardSpec& spec) {
  spec.validate();
  std::vector<QuadtreeMarker> markers;
  if (spec.type != BoardType::kQuadtree) return markers;
  const double s = spec.square_m;
  for (int r = 0; r < spec.rows; ++r)
    for (int c = 0; c < spec.cols; ++c) {
      const int level = quadtreeLevel(spec, r, c), n = 1 << level;
      const double cell = s / n, edge = spec.marker_m / n, inset = 0.5 * (cell - edge);
      for (int sr = 0; sr < n; ++sr)
        for (int sc = 0; sc < n; ++sc) {
          QuadtreeMarker m;
          m.top_left = Eigen::Vector2d(c * s + sc * cell + inset, r * s + sr * cell + inset);
          m.edge_m = edge;
          m.cell_m = cell;
          m.level = level;
          markers.push_back(m);
        }
    }
  return markers;
}

const char* toString(AprilGridLayout layout) {
  return layout == AprilGridLayout::kKalibr ? "kalibr" : "previz";
}

GridCell aprilGridTagCell(const BoardSpec& spec, int tag_index) {
  const int r = tag_index / spec.cols, c = tag_index % spec.cols;
  return {spec.layout == AprilGridLayout::kKalibr ? spec.rows - 1 - r : r, c};
}

int aprilGridTagIndex(const BoardSpec& spec, int row, int col) {
  return (spec.layout == AprilGridLayout::kKalibr ? spec.rows - 1 - row : row) * spec.cols + col;
}

int aprilGridPointId(const BoardSpec& spec, int tag_index, int corner) {
  if (spec.layout == AprilGridLayout::kPreviz) return 4 * tag_index + corner;
  // Kalibr (aprilgrid): tag row rb from the bottom; the corner grid has 2 cols points a row.
  const int rb = tag_index / spec.cols, c = tag_index % spec.cols, width = 2 * spec.cols;
  const int bl = 2 * rb * width + 2 * c;
  switch (corner) {
    case 0: return bl;
    case 1: return bl + 1;
    case 2: return bl + width + 1;
    default: return bl + width;
  }
}

Eigen::Vector2d BoardSpec::size_m() const {
  switch (type) {
    case BoardType::kChessboard:
    case BoardType::kCharuco:
    case BoardType::kCircles:  // circle centres at (c + 1/2, r + 1/2) pitches
    case BoardType::kQuadtree:
      return {cols * square_m, rows * square_m};
    case BoardType::kAprilGrid:  // Kalibr: corner squares of the gap size around every tag
      return {cols * square_m + (cols + 1) * marker_m, rows * square_m + (rows + 1) * marker_m};
  }
  return Eigen::Vector2d::Zero();
}

std::vector<BoardPoint> boardPoints(const BoardSpec& spec) {
  spec.validate();
  std::vector<BoardPoint> points;
  const double s = spec.square_m;
  switch (spec.type) {
    case BoardType::kChessboard:
    case BoardType::kCharuco:
      points.reserve(static_cast<size_t>((spec.rows - 1) * (spec.cols - 1)));
      for (int r = 0; r + 1 < spec.rows; ++r)
        for (int c = 0; c + 1 < spec.cols; ++c)
          points.push_back({r * (spec.cols - 1) + c, Eigen::Vector3d((c + 1) * s, (r + 1) * s, 0)});
      break;
    case BoardType::kAprilGrid: {
      const double g = spec.marker_m;
      points.reserve(static_cast<size_t>(4 * spec.rows * spec.cols));
      for (int tag = 0; tag < spec.rows * spec.cols; ++tag) {
        const GridCell cell = aprilGridTagCell(spec, tag);
        const double x0 = g + cell.col * (s + g), y0 = g + cell.row * (s + g);  // top-left as printed
        // bl, br, tr, tl as printed (libapriltag's p[0..3]).
        const Eigen::Vector3d corners[4] = {{x0, y0 + s, 0}, {x0 + s, y0 + s, 0}, {x0 + s, y0, 0}, {x0, y0, 0}};
        for (int q = 0; q < 4; ++q) points.push_back({aprilGridPointId(spec, tag, q), corners[q]});
      }
      break;
    }
    case BoardType::kCircles:
      points.reserve(static_cast<size_t>(spec.rows * spec.cols));
      for (int r = 0; r < spec.rows; ++r)
        for (int c = 0; c < spec.cols; ++c)
          points.push_back({r * spec.cols + c, Eigen::Vector3d((c + 0.5) * s, (r + 0.5) * s, 0)});
      break;
    case BoardType::kQuadtree: {
      const std::vector<QuadtreeMarker> markers = quadtreeMarkers(spec);
      points.reserve(4 * markers.size());
      for (size_t i = 0; i < markers.size(); ++i) {
        const Eigen::Vector2d& p = markers[i].top_left;
        const double e = markers[i].edge_m;
        const int id = 4 * static_cast<int>(i);
        // OpenCV's aruco corner order: tl, tr, br, bl as printed (clockwise on the print).
        points.push_back({id + 0, Eigen::Vector3d(p.x(), p.y(), 0)});
        points.push_back({id + 1, Eigen::Vector3d(p.x() + e, p.y(), 0)});
        points.push_back({id + 2, Eigen::Vector3d(p.x() + e, p.y() + e, 0)});
        points.push_back({id + 3, Eigen::Vector3d(p.x(), p.y() + e, 0)});
      }
      break;
    }
  }
  return points;
}

namespace {
// spec.validate(), its error naming the file too.
void validateIn(const BoardSpec& spec, const std::string& file) {
  try {
    spec.validate();
  } catch (const Error& e) {
    ErrorContext context = e.context();
    context.file = file;
    throw Error(e.message(), context);
  }
}
}  // namespace

nlohmann::json boardToJson(const BoardSpec& spec) {
  nlohmann::json j;
  j["type"] = toString(spec.type);
  j["rows"] = spec.rows;
  j["cols"] = spec.cols;
  j["square_m"] = spec.square_m;
  j["marker_m"] = spec.marker_m;
  j["circle_radius_m"] = spec.circle_radius_m;
  j["dictionary"] = spec.dictionary;
  j["first_id"] = spec.first_id;
  j["legacy_pattern"] = spec.legacy_pattern;
  j["margin_m"] = spec.margin_m;
  if (spec.type == BoardType::kQuadtree) j["levels"] = spec.levels;
  if (spec.type == BoardType::kAprilGrid) {
    j["layout"] = toString(spec.layout);
    j["tag_border_cells"] = spec.tag_border_cells;
  }
  j["units"] = "m";
  j["frame"] = "origin at the top-left outer corner of the pattern, x along columns, y down rows";
  return j;
}

BoardSpec boardFromJson(const nlohmann::json& j, const std::string& file) {
  auto fieldError = [&](const std::string& field, const std::string& what) {
    ErrorContext context;
    context.file = file;
    context.field = field;
    return Error("board: " + field + " " + what, context);
  };
  if (!j.is_object()) throw fieldError("(root)", "must be a JSON object");
  auto number = [&](const char* key, double fallback, bool required) {
    if (!j.contains(key)) {
      if (required) throw fieldError(key, "is missing");
      return fallback;
    }
    const auto& v = j.at(key);
    if (!v.is_number()) throw fieldError(key, "must be a number (got " + v.dump() + ")");
    return v.get<double>();
  };
  auto integer = [&](const char* key, int fallback, bool required) {
    if (!j.contains(key)) {
      if (required) throw fieldError(key, "is missing");
      return fallback;
    }
    const auto& v = j.at(key);
    if (!v.is_number_integer()) throw fieldError(key, "must be an integer (got " + v.dump() + ")");
    const auto x = v.get<long long>();
    if (x < -1000000 || x > 1000000) throw fieldError(key, "is out of range (got " + v.dump() + ")");
    return static_cast<int>(x);
  };

  BoardSpec spec;
  if (!j.contains("type")) throw fieldError("type", "is missing");
  if (!j.at("type").is_string()) throw fieldError("type", "must be a string");
  spec.type = boardTypeFromString(j.at("type").get<std::string>(), file);
  spec.rows = integer("rows", spec.rows, true);
  spec.cols = integer("cols", spec.cols, true);
  spec.square_m = number("square_m", spec.square_m, true);
  spec.marker_m = number("marker_m", spec.marker_m, false);
  spec.circle_radius_m = number("circle_radius_m", spec.circle_radius_m, false);
  spec.first_id = integer("first_id", spec.first_id, false);
  spec.margin_m = number("margin_m", spec.margin_m, false);
  if (j.contains("levels") && spec.type != BoardType::kQuadtree)
    throw fieldError("levels", "applies to quadtree boards only (this board is a " +
                                   std::string(toString(spec.type)) + ")");
  spec.levels = integer("levels", spec.levels, false);
  if (j.contains("dictionary")) {
    if (!j.at("dictionary").is_string()) throw fieldError("dictionary", "must be a string");
    spec.dictionary = j.at("dictionary").get<std::string>();
  }
  for (const char* key : {"layout", "tag_border_cells"})
    if (j.contains(key) && spec.type != BoardType::kAprilGrid)
      throw fieldError(key, "applies to aprilgrid boards only (this board is a " + std::string(toString(spec.type)) + ")");
  if (j.contains("layout")) {
    const auto& v = j.at("layout");
    if (!v.is_string() || (v != "previz" && v != "kalibr"))
      throw fieldError("layout", "must be \"previz\" or \"kalibr\" (got " + v.dump() + ")");
    spec.layout = v == "kalibr" ? AprilGridLayout::kKalibr : AprilGridLayout::kPreviz;
  }
  spec.tag_border_cells = integer("tag_border_cells", spec.tag_border_cells, false);
  if (j.contains("legacy_pattern")) {
    if (!j.at("legacy_pattern").is_boolean()) throw fieldError("legacy_pattern", "must be true or false");
    spec.legacy_pattern = j.at("legacy_pattern").get<bool>();
  }
  validateIn(spec, file);
  return spec;
}

namespace {

// Kalibr's target YAML (kalibr/wiki "Calibration targets"): aprilgrid or checkerboard.
BoardSpec readKalibrTarget(const std::filesystem::path& path) {
  const std::string file = path.string();
  std::ifstream in(path);
  if (!in) throw Error("board: cannot read the file", ErrorContext{file, "", std::nullopt, ""});
  std::stringstream text;
  text << in.rdbuf();
  const detail::YamlNode root = detail::YamlSubsetParser(text.str(), path).parse();
  auto fieldError = [&](const std::string& field, const std::string& what) {
    ErrorContext context;
    context.file = file;
    context.field = field;
    return Error("board (Kalibr target): " + field + " " + what, context);
  };
  if (root.kind != detail::YamlNode::Kind::kMap) throw fieldError("(root)", "must be a map of 'key: value' lines");
  auto scalar = [&](const char* key) -> const std::string& {
    const detail::YamlNode* n = root.find(key);
    if (n == nullptr) throw fieldError(key, "is missing");
    if (n->kind != detail::YamlNode::Kind::kScalar) throw fieldError(key, "must be a single value");
    return n->scalar;
  };
  auto number = [&](const char* key) {
    const std::string& s = scalar(key);
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (s.empty() || end != s.c_str() + s.size() || !std::isfinite(v))
      throw fieldError(key, "must be a number (got '" + s + "')");
    return v;
  };
  auto integer = [&](const char* key) {
    const double v = number(key);
    if (v != std::floor(v) || v < 1 || v > 1000) throw fieldError(key, "must be a whole number in [1, 1000]");
    return static_cast<int>(v);
  };
  const std::string type = scalar("target_type");
  BoardSpec spec;
  if (type == "aprilgrid") {
    // tagSize: the tag's black square edge; tagSpacing: the gap as a fraction of it. Kalibr prints
    // tag36h11 with a 2-cell black border and numbers from the bottom left.
    spec.type = BoardType::kAprilGrid;
    spec.cols = integer("tagCols");
    spec.rows = integer("tagRows");
    spec.square_m = number("tagSize");
    spec.marker_m = number("tagSpacing") * spec.square_m;
    spec.dictionary = "tag36h11";
    spec.layout = AprilGridLayout::kKalibr;
    spec.tag_border_cells = 2;
  } else if (type == "checkerboard") {
    // targetCols / targetRows count inner corners; previz counts squares.
    spec.type = BoardType::kChessboard;
    spec.cols = integer("targetCols") + 1;
    spec.rows = integer("targetRows") + 1;
    spec.square_m = number("rowSpacingMeters");
    if (std::abs(number("colSpacingMeters") - spec.square_m) > 1e-9)
      throw fieldError("colSpacingMeters", "must equal rowSpacingMeters (previz's chessboards have square cells)");
  } else {
    throw fieldError("target_type", "must be 'aprilgrid' or 'checkerboard' (got '" + type + "')");
  }
  validateIn(spec, file);
  return spec;
}

}  // namespace

BoardSpec readBoard(const std::filesystem::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".yaml" || ext == ".yml") return readKalibrTarget(path);
  return boardFromJson(readJsonFile(path), path.string());
}

void writeBoard(const BoardSpec& spec, const std::filesystem::path& path) {
  validateIn(spec, path.string());
  writeJsonAtomic(path, boardToJson(spec));
}

}  // namespace previz
