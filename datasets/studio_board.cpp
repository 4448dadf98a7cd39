// Printed calibration boards as flat primitives. Every pattern is evaluated analytically in
// board coordinates (metres), with cells of marker/tag bitmaps looked up by exact metric
// bounds, so each black/white edge lies exactly where core/board.h's boardPoints() says.
#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/aruco.hpp>

#include "core/error.h"
#include "datasets/detail/studio_detail.h"

namespace previz::synth {

namespace {

class BoardPrimitive final : public Primitive {
 public:
  BoardPrimitive(const BoardSpec& spec, const Pose& T_world_board)
      : spec_(spec), R_(T_world_board.linear()), t_(T_world_board.translation()) {
    spec.validate();
    size_ = spec.size_m();
    if (spec.type == BoardType::kCharuco) buildCharuco();
    if (spec.type == BoardType::kQuadtree) buildQuadtree();
    if (spec.type == BoardType::kAprilGrid)  // in print order: row-major from the top left
      for (int r = 0; r < spec.rows; ++r)
        for (int c = 0; c < spec.cols; ++c)
          tag_bitmaps_.push_back(detail::tag36h11Bitmap(spec.first_id + aprilGridTagIndex(spec, r, c)));
    const Eigen::Vector2d lo(-spec.margin_m, -spec.margin_m);
    const Eigen::Vector2d hi = size_ + Eigen::Vector2d(spec.margin_m, spec.margin_m);
    lo_ = lo;
    hi_ = hi;
    const Eigen::Vector3d centre_board(0.5 * (lo.x() + hi.x()), 0.5 * (lo.y() + hi.y()), 0);
    bound_centre = T_world_board * centre_board;
    bound_radius = 0.5 * (hi - lo).norm() * (1 + 1e-9) + 1e-9;
    // Uniform lighting over the board (its size is small against the light's distance).
    front_light_ = static_cast<float>(detail::kFillLight +
                                      detail::kKeyLightGain * detail::keyLight(bound_centre, -R_.col(2)));
    back_light_ = static_cast<float>(detail::kFillLight +
                                     detail::kKeyLightGain * detail::keyLight(bound_centre, R_.col(2)));
  }

  bool intersect(const Ray& ray, double t_min, Hit& hit) const override {
    const Eigen::Vector3d o = R_.transpose() * (ray.origin - t_);
    const Eigen::Vector3d d = R_.transpose() * ray.dir;
    if (d.z() == 0) return false;
    const double t = -o.z() / d.z();
    if (!(t > t_min && t < hit.t)) return false;
    const double x = o.x() + t * d.x(), y = o.y() + t * d.y();
    if (x < lo_.x() || x > hi_.x() || y < lo_.y() || y > hi_.y()) return false;
    hit.t = t;
    hit.cls = ObjectClass::kBoard;
    hit.object = 0;
    // The print faces -z (board z points into the board, away from its reader).
    hit.normal = d.z() > 0 ? Eigen::Vector3d(-R_.col(2)) : Eigen::Vector3d(R_.col(2));
    return true;
  }

  void shade(const Ray& ray, Hit& hit) const override {
    const Eigen::Vector3d o = R_.transpose() * (ray.origin - t_);
    const Eigen::Vector3d d = R_.transpose() * ray.dir;
    if (d.z() <= 0) {  // the back of the board
      hit.rgb = Eigen::Vector3f(0.35f, 0.35f, 0.35f) * back_light_;
      return;
    }
    const double x = o.x() + hit.t * d.x(), y = o.y() + hit.t * d.y();
    hit.rgb = (isBlack(x, y) ? detail::kInkBlack : detail::kPaperWhite) * front_light_;
  }

  // Pattern value at board coordinates (x, y), metres. Public for the tests' orthographic
  // renders through the same code path (they go through trace() anyway).
  bool isBlack(double x, double y) const {
    if (x < 0 || y < 0 || x >= size_.x() || y >= size_.y()) return false;  // margin
    const double s = spec_.square_m;
    switch (spec_.type) {
      case BoardType::kChessboard: {
        const int c = std::min(static_cast<int>(x / s), spec_.cols - 1);
        const int r = std::min(static_cast<int>(y / s), spec_.rows - 1);
        return (r + c) % 2 == 0;
      }
      case BoardType::kCharuco: {
        const int c = std::min(static_cast<int>(x / s), spec_.cols - 1);
        const int r = std::min(static_cast<int>(y / s), spec_.rows - 1);
        const int marker = marker_of_square_[r * spec_.cols + c];
        if (marker < 0) return true;  // black square
        const double m = spec_.marker_m;
        const double mx = x - (c * s + 0.5 * (s - m)), my = y - (r * s + 0.5 * (s - m));
        if (mx < 0 || my < 0 || mx >= m || my >= m) return false;
        const double cell = m / marker_cells_;
        const int bx = std::min(static_cast<int>(mx / cell), marker_cells_ - 1);
        const int by = std::min(static_cast<int>(my / cell), marker_cells_ - 1);
        return marker_bits_[(marker * marker_cells_ + by) * marker_cells_ + bx] == 0;
      }
      case BoardType::kAprilGrid: {
        const double g = spec_.marker_m, pitch = s + g;
        const int c = static_cast<int>(x / pitch), r = static_cast<int>(y / pitch);
        const double lx = x - c * pitch, ly = y - r * pitch;
        const bool gap_x = lx < g, gap_y = ly < g;
        if (gap_x && gap_y) return true;  // Kalibr's corner squares
        if (gap_x || gap_y || c >= spec_.cols || r >= spec_.rows) return false;
        // The black square is the bitmap's (one border cell) widened by the extra border cells.
        const int extra = spec_.tag_border_cells - 1, black = detail::kTagBlackWidth + 2 * extra;
        const double cell = s / black;
        const int bx = std::min(static_cast<int>((lx - g) / cell), black - 1) - extra;
        const int by = std::min(static_cast<int>((ly - g) / cell), black - 1) - extra;
        if (bx < 0 || by < 0 || bx >= detail::kTagBlackWidth || by >= detail::kTagBlackWidth) return true;
        const std::uint8_t* bitmap = tag_bitmaps_[r * spec_.cols + c];
        return bitmap[(by + 1) * detail::kTagBitmapWidth + bx + 1] == 0;
      }
      case BoardType::kCircles: {
        const int c = std::min(static_cast<int>(x / s), spec_.cols - 1);
        const int r = std::min(static_cast<int>(y / s), spec_.rows - 1);
        const double dx = x - (c + 0.5) * s, dy = y - (r + 0.5) * s;
        const double d = std::sqrt(dx * dx + dy * dy), R = spec_.circle_radius_m;
        if (d >= R) return false;
        if (d >= 2 * R / 3) return true;
        return d < R / 3;
      }
      case BoardType::kQuadtree: {
        const int c = std::min(static_cast<int>(x / s), spec_.cols - 1);
        const int r = std::min(static_cast<int>(y / s), spec_.rows - 1);
        const int n = 1 << cell_level_[r * spec_.cols + c];
        const double cell = s / n;
        const int sc = std::min(static_cast<int>((x - c * s) / cell), n - 1);
        const int sr = std::min(static_cast<int>((y - r * s) / cell), n - 1);
        const int marker = cell_first_marker_[r * spec_.cols + c] + sr * n + sc;
        const QuadtreeMarker& qm = quadtree_[static_cast<size_t>(marker)];
        const double mx = x - qm.top_left.x(), my = y - qm.top_left.y();
        if (mx < 0 || my < 0 || mx >= qm.edge_m || my >= qm.edge_m) return false;
        const double bit = qm.edge_m / marker_cells_;
        const int bx = std::min(static_cast<int>(mx / bit), marker_cells_ - 1);
        const int by = std::min(static_cast<int>(my / bit), marker_cells_ - 1);
        return marker_bits_[(marker * marker_cells_ + by) * marker_cells_ + bx] == 0;
      }
    }
    return false;
  }

 private:
  void buildCharuco() {
    // OpenCV >= 4.6 layout: the top-left square is black, markers fill the white squares in
    // row-major order. The legacy (< 4.6) layout differs only for an even number of rows,
    // whose top-left square is then white.
    const bool flip = spec_.legacy_pattern && spec_.rows % 2 == 0;
    marker_of_square_.assign(static_cast<size_t>(spec_.rows * spec_.cols), -1);
    int k = 0;
    for (int r = 0; r < spec_.rows; ++r)
      for (int c = 0; c < spec_.cols; ++c) {
        const bool black = ((r + c) % 2 == 0) != flip;
        if (!black) marker_of_square_[r * spec_.cols + c] = k++;
      }
    storeMarkerBits(k);
  }

  // Quadtree (core/board.h): per outer cell its level and first marker, markers in core's order.
  void buildQuadtree() {
    quadtree_ = quadtreeMarkers(spec_);
    int first = 0;
    for (int r = 0; r < spec_.rows; ++r)
      for (int c = 0; c < spec_.cols; ++c) {
        const int level = quadtreeLevel(spec_, r, c);
        cell_first_marker_.push_back(first);
        cell_level_.push_back(level);
        first += 1 << (2 * level);
      }
    storeMarkerBits(static_cast<int>(quadtree_.size()));
  }

  // The bitmaps of markers first_id .. first_id + count - 1, one-cell black border included.
  void storeMarkerBits(int count) {
    const auto dictionary = cv::aruco::getPredefinedDictionary(openCvDictionaryId(spec_.dictionary));
    marker_cells_ = dictionary->markerSize + 2;
    marker_bits_.resize(static_cast<size_t>(count * marker_cells_ * marker_cells_));
    for (int i = 0; i < count; ++i) {
      cv::Mat image;
      cv::aruco::drawMarker(dictionary, spec_.first_id + i, marker_cells_, image, 1);
      for (int y = 0; y < marker_cells_; ++y)
        for (int x = 0; x < marker_cells_; ++x)
          marker_bits_[(i * marker_cells_ + y) * marker_cells_ + x] = image.at<std::uint8_t>(y, x) > 127 ? 1 : 0;
    }
  }

  BoardSpec spec_;
  std::vector<QuadtreeMarker> quadtree_;
  std::vector<int> cell_level_, cell_first_marker_;
  Eigen::Matrix3d R_;
  Eigen::Vector3d t_;
  Eigen::Vector2d size_, lo_, hi_;
  float front_light_ = 1, back_light_ = 1;
  int marker_cells_ = 0;
  std::vector<int> marker_of_square_;
  std::vector<std::uint8_t> marker_bits_;
  std::vector<const std::uint8_t*> tag_bitmaps_;
};

}  // namespace

std::shared_ptr<const Primitive> makeBoard(const BoardSpec& spec, const Pose& T_world_board) {
  return std::make_shared<BoardPrimitive>(spec, T_world_board);
}

BoardSpec defaultBoard(BoardType type) {
  BoardSpec spec;
  spec.type = type;
  switch (type) {
    case BoardType::kChessboard:
      spec.rows = 7;
      spec.cols = 10;
      spec.square_m = 0.06;
      spec.margin_m = 0.06;  // a white border of one square helps OpenCV's quad search
      break;
    case BoardType::kCharuco:
      // Odd rows: OpenCV 4.6 and older releases agree on the layout (legacy_pattern moot).
      spec.rows = 7;
      spec.cols = 10;
      spec.square_m = 0.06;
      spec.marker_m = 0.045;
      spec.dictionary = "DICT_5X5_1000";
      spec.margin_m = 0.02;
      break;
    case BoardType::kAprilGrid:
      spec.rows = 6;
      spec.cols = 6;
      spec.square_m = 0.08;
      spec.marker_m = 0.024;  // Kalibr's tagSpacing 0.3
      spec.dictionary = "tag36h11";
      spec.margin_m = 0.02;
      break;
    case BoardType::kCircles:
      spec.rows = 6;
      spec.cols = 8;
      spec.square_m = 0.08;
      spec.circle_radius_m = 0.03;
      spec.margin_m = 0.02;
      break;
    case BoardType::kQuadtree:
      // 5 x 5 cells of 12 cm, 3 levels: 16 markers of 96 mm on the outer ring, 32 of 48 mm
      // on the next, 16 of 24 mm in the centre cell (64 markers, 256 points). Marker edge
      // 0.8 of its cell: the white gap between markers (0.2 cell) and the marker's black
      // border bit (0.8 / 6 cell for 4x4 codes) bound the refinement windows alike.
      spec.rows = 5;
      spec.cols = 5;
      spec.square_m = 0.12;
      spec.marker_m = 0.096;
      spec.levels = 3;
      spec.dictionary = "DICT_4X4_250";
      spec.margin_m = 0.02;
      break;
  }
  spec.validate();
  return spec;
}

}  // namespace previz::synth
