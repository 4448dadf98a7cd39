// AprilGrid (Kalibr's pattern, tag36h11): libapriltag finds the tags; every tag corner touches a
// black corner square diagonally, so it is an X-junction like a chessboard corner and is refined
// by cornerSubPix (as Kalibr does), with a window that stays inside the tag's black border and
// the gap. Kalibr prints its tags with a 2-cell black border (BoardSpec::tag_border_cells), which
// libapriltag's tag36h11 (1 cell) does not decode: the detector then uses tag36h11's own code
// table with the border widened (the data bits one cell further in).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

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

// A tag's corner q on the board (metres; libapriltag's p[0..3] is bl, br, tr, tl as printed).
cv::Point2d aprilGridCorner(const BoardSpec& board, int tag, int q) {
  const double s = board.square_m, g = board.marker_m;
  const GridCell cell = aprilGridTagCell(board, tag);
  const double x0 = g + cell.col * (s + g), y0 = g + cell.row * (s + g);
  return {(q == 1 || q == 2) ? x0 + s : x0, (q == 0 || q == 1) ? y0 + s : y0};
}

// The part of the image the board's tags can be in: a pass at decimation 4 (about a sixteenth of
// a full-resolution pass's cost) finds the larger tags; the homography from the board to the
// image through their corners (RANSAC: a tag decoded under a wrong id would pull a least-squares
// fit) predicts every tag of the board, and the window is the box of those in front of the
// camera, grown by a predicted tag edge and 5 % of the image (the lens bends the image away
// from a homography, most at the edges), clipped to the image. Its corner is on a multiple of 24
// pixels, so libapriltag's 4-pixel threshold tiles (at decimations 1, 2 and 3) fall where they
// do on the whole image: on multicam.capture's 1441 images the same tags and points are found,
// every corner within 0.0004 px of the whole image's. The whole image when fewer than two tags
// of the board are found once (small tags, no homography to trust).
cv::Rect boardWindow(apriltag_detector_t* detector, const image_u8_t& im, const BoardSpec& board) {
  const cv::Rect whole(0, 0, im.width, im.height);
  detector->quad_decimate = 4.0f;
  image_u8_t copy = im;
  std::unique_ptr<zarray_t, DetectionsDeleter> found(apriltag_detector_detect(detector, &copy));
  const int n_tags = board.rows * board.cols;
  std::map<int, int> count;
  for (int k = 0; k < zarray_size(found.get()); ++k) {
    apriltag_detection_t* det = nullptr;
    zarray_get(found.get(), k, &det);
    ++count[det->id];
  }
  std::vector<cv::Point2f> from, to;
  for (int k = 0; k < zarray_size(found.get()); ++k) {
    apriltag_detection_t* det = nullptr;
    zarray_get(found.get(), k, &det);
    const int index = det->id - board.first_id;
    if (index < 0 || index >= n_tags || count[det->id] != 1) continue;
    for (int q = 0; q < 4; ++q) {
      from.emplace_back(aprilGridCorner(board, index, q));
      to.emplace_back(static_cast<float>(det->p[q][0]), static_cast<float>(det->p[q][1]));
    }
  }
  if (from.size() < 8) return whole;
  std::vector<unsigned char> inliers;
  const cv::Mat H = cv::findHomography(from, to, cv::RANSAC, std::max(3.0, 0.01 * im.width), inliers);
  if (H.empty() || std::count(inliers.begin(), inliers.end(), 1) < 8) return whole;
  double x_lo = std::numeric_limits<double>::infinity(), y_lo = x_lo, x_hi = -x_lo, y_hi = -x_lo, edge = 0;
  for (int tag = 0; tag < n_tags; ++tag) {
    std::array<cv::Point2d, 4> px;
    bool in_front = true;
    for (int q = 0; q < 4; ++q) {
      const cv::Point2d b = aprilGridCorner(board, tag, q);
      const double w = H.at<double>(2, 0) * b.x + H.at<double>(2, 1) * b.y + H.at<double>(2, 2);
      if (!(w > 0)) {
        in_front = false;
        break;
      }
      px[q] = {(H.at<double>(0, 0) * b.x + H.at<double>(0, 1) * b.y + H.at<double>(0, 2)) / w,
               (H.at<double>(1, 0) * b.x + H.at<double>(1, 1) * b.y + H.at<double>(1, 2)) / w};
    }
    if (!in_front) continue;  // not whole in front of the camera: never found
    for (int q = 0; q < 4; ++q) {
      edge = std::max(edge, cv::norm(px[q] - px[(q + 1) % 4]));
      x_lo = std::min(x_lo, px[q].x), x_hi = std::max(x_hi, px[q].x);
      y_lo = std::min(y_lo, px[q].y), y_hi = std::max(y_hi, px[q].y);
    }
  }
  if (!(x_lo <= x_hi)) return whole;
  const double mx = edge + 0.05 * im.width, my = edge + 0.05 * im.height;
  constexpr int kAlign = 24;  // a multiple of the threshold tile (4) at decimations 1, 2 and 3
  auto clampTo = [](double v, int hi) { return static_cast<int>(std::clamp(v, 0.0, static_cast<double>(hi))); };
  const int x0 = clampTo(std::floor(x_lo - mx), im.width) / kAlign * kAlign;
  const int y0 = clampTo(std::floor(y_lo - my), im.height) / kAlign * kAlign;
  const int x1 = clampTo(std::ceil(x_hi + mx) + 1, im.width), y1 = clampTo(std::ceil(y_hi + my) + 1, im.height);
  if (x1 - x0 < 8 || y1 - y0 < 8) return whole;  // predicted out of the image: trust the search, not the fit
  return cv::Rect(x0, y0, x1 - x0, y1 - y0);
}

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
  // The passes search only the part of the image the board can cover (boardWindow, from a pass
  // at a quarter of the resolution): a rig capture's board is often a tenth of the frame.
  // The window is a prediction from the board file: a tag found within 1.5 tag edges of a side
  // of it that is not the image's says the board goes on beyond it (another board than the
  // file's, a lens the homography misses), and every pass is run again on the whole image.
  std::unique_ptr<zarray_t, DetectionsDeleter> passes[3];
  auto search = [&](const cv::Rect& window) {
    mine.clear(), seen.clear(), other_tags = 0;
    image_u8_t sub{window.width, window.height, im.stride, im.buf + window.y * im.stride + window.x};
    const float decimation[3] = {1.0f, 2.0f, 3.0f};
    bool near_side = false;
    for (int pass = 0; pass < 3; ++pass) {
      passes[pass].reset();
      if (pass > 0 && static_cast<int>(seen.size()) == n_tags) continue;
      detector.get()->quad_decimate = decimation[pass];
      passes[pass].reset(apriltag_detector_detect(detector.get(), &sub));
      std::map<int, int> found;
      std::vector<apriltag_detection_t*> found_tags;
      for (int k = 0; k < zarray_size(passes[pass].get()); ++k) {
        apriltag_detection_t* det = nullptr;
        zarray_get(passes[pass].get(), k, &det);
        double edge = 0, x_lo = det->p[0][0], x_hi = x_lo, y_lo = det->p[0][1], y_hi = y_lo;
        for (int q = 0; q < 4; ++q) {
          edge = std::max(edge, std::hypot(det->p[q][0] - det->p[(q + 1) % 4][0], det->p[q][1] - det->p[(q + 1) % 4][1]));
          x_lo = std::min(x_lo, det->p[q][0]), x_hi = std::max(x_hi, det->p[q][0]);
          y_lo = std::min(y_lo, det->p[q][1]), y_hi = std::max(y_hi, det->p[q][1]);
        }
        const double reach = 1.5 * edge;
        near_side |= (window.x > 0 && x_lo < reach) || (window.y > 0 && y_lo < reach) ||
                     (window.br().x < im.width && x_hi > window.width - reach) ||
                     (window.br().y < im.height && y_hi > window.height - reach);
        for (int q = 0; q < 4; ++q) det->p[q][0] += window.x, det->p[q][1] += window.y;
        det->c[0] += window.x, det->c[1] += window.y;
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
    return !near_side;
  };
  const cv::Rect whole(0, 0, im.width, im.height);
  const cv::Rect window = boardWindow(detector.get(), im, board);
  if (!search(window) && window != whole) search(whole);
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
  auto cornerOnBoard = [&](int tag, int q) { return cv::Point2f(aprilGridCorner(board, tag, q)); };
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
