// AprilGrid (Kalibr's pattern, tag36h11): libapriltag finds the tags; every tag corner touches a
// black corner square diagonally, so it is an X-junction like a chessboard corner and is refined
// by cornerSubPix (as Kalibr does), with a window that stays inside the tag's black border and
// the gap. Kalibr prints its tags with a 2-cell black border (BoardSpec::tag_border_cells), which
// libapriltag's tag36h11 (1 cell) does not decode: the detector then uses tag36h11's own code
// table with the border widened (the data bits one cell further in).
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <string>

#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "calib/detail/detect_common.h"
#include "core/board.h"

namespace previz::calib::detail {

namespace {

// One detector per thread, built on first use and destroyed when the thread ends: adding the
// family builds the decoding table of every code within 2 bit flips, too costly to repeat per
// image (STYLE.md rule 10).
class TagDetector {
 public:
  explicit TagDetector(int border_cells) : family_(tag36h11_create()), detector_(apriltag_detector_create()) {
    // A wider black border: the same codes, bits, quiet zone; the bit grid moves inward.
    const int extra = border_cells - 1;
    family_->width_at_border += 2 * extra;
    family_->total_width += 2 * extra;
    for (unsigned i = 0; i < family_->nbits; ++i) {
      family_->bit_x[i] += extra;
      family_->bit_y[i] += extra;
    }
    apriltag_detector_add_family_bits(detector_, family_, 2);
    // Full resolution quads: grid tags may be small; refine_edges fits each edge to the
    // gradient along it; one thread (callers parallelise over images).
    detector_->quad_decimate = 1.0f;  // set per pass
    detector_->quad_sigma = 0.0f;
    detector_->refine_edges = true;
    detector_->decode_sharpening = 0.25;
    detector_->nthreads = 1;
  }
  ~TagDetector() {
    apriltag_detector_destroy(detector_);
    tag36h11_destroy(family_);
  }
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;
  apriltag_detector_t* get() { return detector_; }
  int blackWidth() const { return family_->width_at_border; }

 private:
  apriltag_family_t* family_;
  apriltag_detector_t* detector_;
};

TagDetector& threadTagDetector(int border_cells) {
  thread_local TagDetector one(1), two(2);
  return border_cells == 2 ? two : one;
}

struct DetectionsDeleter {
  void operator()(zarray_t* z) const { apriltag_detections_destroy(z); }
};

}  // namespace

void detectAprilGrid(const DetectInput& input, const BoardSpec& board, ViewObservations& out) {
  const DetectOptions& options = input.options();
  TagDetector& detector = threadTagDetector(board.tag_border_cells);
  const cv::Mat& grey = input.grey();
  image_u8_t im{grey.cols, grey.rows, static_cast<int32_t>(grey.step[0]),
                const_cast<uint8_t*>(grey.ptr<uint8_t>())};
  const int n_tags = board.rows * board.cols;
  std::vector<apriltag_detection_t*> mine;
  std::map<int, int> seen;
  int other_tags = 0;
  // Where a tag's corner touches a corner square diagonally the two dark regions can form one
  // component and libapriltag loses the tag (it happens on crisp prints); at another decimation
  // the pixels meet differently. So tags missing at full resolution are looked for again at a
  // half and a third (libapriltag refines those edges at full resolution), keeping the earlier
  // passes' (Kalibr's EuRoC photo: 32, 35 and 36 of its 36 tags at 1, 2 and 3).
  std::unique_ptr<zarray_t, DetectionsDeleter> passes[3];
  const float decimation[3] = {1.0f, 2.0f, 3.0f};
  for (int pass = 0; pass < 3; ++pass) {
    if (pass > 0 && static_cast<int>(seen.size()) == n_tags) break;
    detector.get()->quad_decimate = decimation[pass];
    passes[pass].reset(apriltag_detector_detect(detector.get(), &im));
    std::map<int, int> found;
    std::vector<apriltag_detection_t*> found_tags;
    for (int k = 0; k < zarray_size(passes[pass].get()); ++k) {
      apriltag_detection_t* det = nullptr;
      zarray_get(passes[pass].get(), k, &det);
      const int index = det->id - board.first_id;
      if (index < 0 || index >= n_tags) {
        if (pass == 0) ++other_tags;
        continue;
      }
      if (pass > 0 && seen.count(det->id)) continue;
      ++found[det->id];
      found_tags.push_back(det);
    }
    for (const auto& [id, count] : found) seen[id] += count;
    mine.insert(mine.end(), found_tags.begin(), found_tags.end());
  }
  if (mine.empty()) {
    out.failure = other_tags == 0 ? "no tag36h11 tags found (tags with a " + std::to_string(board.tag_border_cells) +
                                        "-cell black border looked for)"
                                  : "no tag of this board found (" + std::to_string(other_tags) +
                                        " other tags)";
    return;
  }

  // libapriltag's corners lie half a pixel off OpenCV's convention (it puts pixel centres at
  // +0.5); they are only the start of cornerSubPix, but the start should be on the corner.
  constexpr double kApriltagPixelOffset = -0.5;
  const double g_over_s = board.marker_m / board.square_m;
  // Per corner: its pixel, window, tag (index on the board and in out.tags), corner 0..3.
  std::vector<cv::Point2f> pts;
  std::vector<RefineWindow> windows;
  std::vector<int> tag_of, corner_of, decoded_of;
  std::vector<double> tag_edge_px;
  int small = 0, at_border = 0;
  for (apriltag_detection_t* det : mine) {
    DecodedTag decoded;
    decoded.id = det->id;
    decoded.bit_errors = det->hamming;
    const int slot = static_cast<int>(out.tags.size());
    if (seen[det->id] != 1) {  // the same id twice: which is the board's?
      decoded.why_not = "id seen " + std::to_string(seen[det->id]) + " times";
      out.tags.push_back(decoded);
      continue;
    }
    std::array<Eigen::Vector2d, 4> px;
    for (int q = 0; q < 4; ++q)
      px[q] = Eigen::Vector2d(det->p[q][0], det->p[q][1]) +
              Eigen::Vector2d::Constant(kApriltagPixelOffset);
    double edge = 0;
    const MarkerCheck check = checkMarker(px, input.size(), options, &edge);
    if (check == MarkerCheck::kTooSmall || check == MarkerCheck::kAtBorder) {
      ++(check == MarkerCheck::kTooSmall ? small : at_border);
      decoded.why_not = check == MarkerCheck::kTooSmall ? "too small" : "at the image border";
      out.tags.push_back(decoded);
      continue;
    }
    // Edges not through a tag corner: the first data cell inside the black border (quadrant-
    // shaped, reached when w > the border's width) and the far sides of the corner square and of
    // the gap (lines g away, reached when sqrt(2) w > g for a window turned by 45 degrees).
    const double cell_px = edge / detector.blackWidth();
    const double free_px = std::min(board.tag_border_cells * cell_px, g_over_s * edge / std::sqrt(2.0));
    RefineWindow window;
    if (options.subpixel)
      window = refineWindow(free_px, options);
    else
      window.half = options.subpixel_window_px;
    const int w = window.half;
    if (w == 0) {
      ++small;
      decoded.why_not = "too small";
      out.tags.push_back(decoded);
      continue;
    }
    out.tags.push_back(decoded);
    const int tag = det->id - board.first_id;
    for (int q = 0; q < 4; ++q) {
      if (nearBorder(px[q], input.size(), options.border_margin_px + w)) continue;
      // libapriltag's p[0..3] is bl, br, tr, tl as printed: core/board.h's corner order.
      tag_of.push_back(tag);
      corner_of.push_back(q);
      decoded_of.push_back(slot);
      pts.emplace_back(static_cast<float>(px[q].x()), static_cast<float>(px[q].y()));
      windows.push_back(window);
      tag_edge_px.push_back(edge);
    }
  }
  std::vector<bool> ok(pts.size(), true);
  if (options.subpixel) ok = refineCorners(input, pts, windows);

  // Where a tag touches its corner squares the dark regions merge when the tag is small or
  // blurred, and libapriltag's quad can then be pulled a few pixels towards a corner square,
  // beyond what cornerSubPix's window can bring back. Every corner is therefore checked against
  // a homography fitted (RANSAC) to the corners of the tags around it: the 3 x 3 block is small
  // enough for the lens to be a homography to a fraction of a pixel there. The same check is
  // what a tag decoded with bit errors must pass to be used at all (a wrong id would put its
  // corners somewhere else on the board).
  const double s = board.square_m, g = board.marker_m;
  auto cornerOnBoard = [&](int tag, int q) {
    const GridCell cell = aprilGridTagCell(board, tag);
    const double x0 = g + cell.col * (s + g), y0 = g + cell.row * (s + g);
    const double x = (q == 1 || q == 2) ? x0 + s : x0, y = (q == 0 || q == 1) ? y0 + s : y0;
    return cv::Point2f(static_cast<float>(x), static_cast<float>(y));
  };
  std::map<std::pair<int, int>, size_t> index_of;  // (tag, corner) -> index in pts
  for (size_t k = 0; k < pts.size(); ++k)
    if (ok[k]) index_of[{tag_of[k], corner_of[k]}] = k;
  std::vector<bool> consistent = ok;
  for (size_t k = 0; k < pts.size(); ++k) {
    if (!ok[k]) continue;
    const GridCell cell = aprilGridTagCell(board, tag_of[k]);
    std::vector<cv::Point2f> from, to;
    for (int dr = -1; dr <= 1; ++dr)
      for (int dc = -1; dc <= 1; ++dc) {
        const int r = cell.row + dr, c = cell.col + dc;
        if ((dr == 0 && dc == 0) || r < 0 || c < 0 || r >= board.rows || c >= board.cols) continue;
        const int other = aprilGridTagIndex(board, r, c);
        for (int q = 0; q < 4; ++q) {
          const auto it = index_of.find({other, q});
          if (it == index_of.end() || out.tags[decoded_of[it->second]].bit_errors > 0) continue;
          from.push_back(cornerOnBoard(other, q));
          to.push_back(pts[it->second]);
        }
      }
    const bool unsure = out.tags[decoded_of[k]].bit_errors > 0;
    if (from.size() < 8) {  // too few neighbours to check against: keep an exact decode
      if (unsure) consistent[k] = false;
      continue;
    }
    const cv::Mat H = cv::findHomography(from, to, cv::RANSAC, 1.0);
    if (H.empty()) {
      if (unsure) consistent[k] = false;
      continue;
    }
    std::vector<cv::Point2f> predicted;
    cv::perspectiveTransform(std::vector<cv::Point2f>{cornerOnBoard(tag_of[k], corner_of[k])}, predicted, H);
    const double tol = std::max(1.0, 0.03 * tag_edge_px[k]);
    if (cv::norm(predicted[0] - pts[k]) > tol) consistent[k] = false;
  }
  for (size_t k = 0; k < pts.size(); ++k) {
    DecodedTag& decoded = out.tags[decoded_of[k]];
    if (consistent[k]) {
      out.points.push_back({aprilGridPointId(board, tag_of[k], corner_of[k]), Eigen::Vector2d(pts[k].x, pts[k].y)});
      decoded.used = true;
      decoded.why_not.clear();
    } else if (!decoded.used && decoded.why_not.empty()) {
      decoded.why_not = !ok[k] ? "corner refinement failed"
                        : decoded.bit_errors > 0
                            ? "decoded with " + std::to_string(decoded.bit_errors) +
                                  " bit errors and not confirmed by the tags around it"
                            : "corners off the homography of the tags around it";
    }
  }
  if (out.points.empty())
    out.failure = std::to_string(mine.size()) + " tags of this board found but none usable (" +
                  std::to_string(small) + " too small, " + std::to_string(at_border) +
                  " at the border)";
}

}  // namespace previz::calib::detail
