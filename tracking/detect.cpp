// libapriltag behind a small RAII owner: one apriltag_detector_t per TagDetector with every
// family of the props added once.
#include "tracking/detect.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>

#include <apriltag/apriltag.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/marker_edges.h"
#include "core/srgb.h"
#include "tracking/detail/families.h"
#include "tracking/props.h"

namespace previz::tracking {

namespace {

ErrorContext field(const std::string& name) {
  ErrorContext c;
  c.field = name;
  return c;
}

struct DetectionsDeleter {
  void operator()(zarray_t* z) const { apriltag_detections_destroy(z); }
};
using Detections = std::unique_ptr<zarray_t, DetectionsDeleter>;

// libapriltag puts pixel centres at +0.5 (its corners are half a pixel off OpenCV's convention;
// calib/detect_aprilgrid.cpp makes the same correction).
constexpr double kApriltagPixelOffset = -0.5;

// Corner refinement (TagDetector::Impl::refineCorners): passes of fitting the four edges from
// the current corners; each edge measured from kCornerMarginPx (or kCornerMarginFraction of it,
// if more) after one corner to as much before the next (the corners' own blur); edges longer
// than kMaxSpanPx are fitted near each end separately (the lens bends them: over 40 px at
// k1 = -0.22, ~0.06 px).
constexpr int kRefinePasses = 2;
constexpr double kCornerMarginPx = 3.0, kCornerMarginFraction = 0.1, kMaxSpanPx = 40.0;

Eigen::Vector2d homography(const Eigen::Matrix3d& H, const Eigen::Vector2d& p) {
  return (H * p.homogeneous()).hnormalized();
}

Eigen::Vector2d centre(const TagDetection& d) {
  return 0.25 * (d.corners_px[0] + d.corners_px[1] + d.corners_px[2] + d.corners_px[3]);
}

double meanSide(const TagDetection& d) {
  double sum = 0;
  for (int q = 0; q < 4; ++q) sum += (d.corners_px[(q + 1) % 4] - d.corners_px[q]).norm();
  return 0.25 * sum;
}

}  // namespace

void DetectorOptions::validate() const {
  auto bad = [](const std::string& f, const std::string& what) { throw Error("detector: " + what, field(f)); };
  if (families.empty()) bad("families", "at least one AprilTag family");
  for (const auto& f : families)
    if (!isKnownFamily(f)) bad("families", "unknown AprilTag family '" + f + "'");
  if (!(decimate >= 1.0f)) bad("decimate", "decimate must be >= 1 (got " + std::to_string(decimate) + ")");
  if (!(sigma >= 0.0f)) bad("sigma", "sigma must be >= 0 (got " + std::to_string(sigma) + ")");
  if (threads < 1) bad("threads", "threads must be >= 1 (got " + std::to_string(threads) + ")");
  if (max_hamming < 0 || max_hamming > 2) bad("max_hamming", "max_hamming must be 0, 1 or 2");
  if (!(decode_sharpening >= 0)) bad("decode_sharpening", "decode_sharpening must be >= 0");
}

struct TagDetector::Impl {
  DetectorOptions options;
  std::vector<detail::FamilyPtr> families;
  apriltag_detector_t* td = nullptr;
  cv::Mat search;  // the rectangle in grey for libapriltag, which blurs it in place
  cv::Mat grey8;   // around one tag, grey from the caller's image (refine_corners)
  cv::Mat patch;   // the same, float, linear light

  ~Impl() {
    if (td) apriltag_detector_destroy(td);  // before the families it references
  }

  // d.corners_px in image's pixels (image: the rectangle searched, grey or BGR). Each of the tag's four edges is fitted as a line (the
  // centroid of its dark -> light step, core/marker_edges.h fitEdgeLine) on a float linear-light
  // patch around the tag, and each corner is where its two edges meet; the black border is one
  // bit wide, the white quiet zone around it one bit (tag36h11, tag25h9, tag16h5: total_width -
  // width_at_border = 2). A corner more than half a bit from libapriltag's is a fit on something
  // else (a neighbour, a shadow's edge), as is one whose edge could not be measured: it keeps
  // libapriltag's. Measured moves: at most 0.39 bit on the studio's witnesses, 0.6 bit at the
  // 99th percentile on the real photos.
  void refineCorners(const cv::Mat& image, const apriltag_family_t& family, TagDetection& d) {
    const std::array<Eigen::Vector2d, 4> start = d.corners_px;
    double side = 0;
    Eigen::Vector2d lo = start[0], hi = start[0];
    for (int q = 0; q < 4; ++q) {
      const double e = (start[(q + 1) % 4] - start[q]).norm();
      side += 0.25 * e;
      lo = lo.cwiseMin(start[q]);
      hi = hi.cwiseMax(start[q]);
    }
    const double bit_px = side / family.width_at_border;
    const double quiet_bits = 0.5 * (family.total_width - family.width_at_border);
    const int margin = 8;  // the profile's reach (4 px) and the 2 x 2 interpolation, with room
    const cv::Rect box = cv::Rect(cv::Point(static_cast<int>(std::floor(lo.x())) - margin,
                                            static_cast<int>(std::floor(lo.y())) - margin),
                                  cv::Point(static_cast<int>(std::ceil(hi.x())) + margin + 1,
                                            static_cast<int>(std::ceil(hi.y())) + margin + 1)) &
                         cv::Rect(0, 0, image.cols, image.rows);
    if (box.width < 4 || box.height < 4) return;
    if (image.channels() == 3)
      cv::cvtColor(image(box), grey8, cv::COLOR_BGR2GRAY);
    else
      grey8 = image(box);
    if (options.linear_light) {
      const float* lut = srgb8ToLinear().data();
      patch.create(box.size(), CV_32F);
      for (int v = 0; v < box.height; ++v) {
        const std::uint8_t* in = grey8.ptr<std::uint8_t>(v);
        float* out = patch.ptr<float>(v);
        for (int u = 0; u < box.width; ++u) out[u] = lut[in[u]];
      }
    } else {
      grey8.convertTo(patch, CV_32F, 1.0 / 255.0);
    }
    // The tag's plane: a unit square, corner q at kSquare[q] (libapriltag's order: its p[0..3]
    // go around the tag, so any assignment that goes around it is a homography of the same quad).
    // Only used to measure the border bit across each edge in the image.
    static const Eigen::Vector2d kSquare[4] = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
    static const cv::Point2f kSquareCv[4] = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
    const Eigen::Vector2d box_tl(box.x, box.y);
    std::array<Eigen::Vector2d, 4> current;
    for (int q = 0; q < 4; ++q) current[q] = start[q] - box_tl;
    for (int pass = 0; pass < kRefinePasses; ++pass) {
      cv::Point2f to[4];
      for (int q = 0; q < 4; ++q)
        to[q] = cv::Point2f(static_cast<float>(current[q].x()), static_cast<float>(current[q].y()));
      cv::Mat Hcv;
      cv::getPerspectiveTransform(kSquareCv, to).convertTo(Hcv, CV_64F);
      Eigen::Matrix3d H;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) H(r, c) = Hcv.at<double>(r, c);
      const Eigen::Vector2d centre_px = homography(H, Eigen::Vector2d(0.5, 0.5));
      // Edge q runs from corner q to corner q + 1: its line near each end (one fit when the edge
      // is short enough, kMaxSpanPx, for the lens's bend to stay below ~0.05 px).
      std::array<std::array<Eigen::Vector3d, 2>, 4> line;  // [edge][0: near corner q, 1: near q + 1]
      std::array<std::array<bool, 2>, 4> ok{};
      for (int q = 0; q < 4; ++q) {
        const Eigen::Vector2d& a = current[q];
        const Eigen::Vector2d& b = current[(q + 1) % 4];
        const Eigen::Vector2d mid_sq = 0.5 * (kSquare[q] + kSquare[(q + 1) % 4]);
        const Eigen::Vector2d inward = (Eigen::Vector2d(0.5, 0.5) - mid_sq) * (2.0 / family.width_at_border);
        const double across = (homography(H, mid_sq + inward) - homography(H, mid_sq)).norm();
        // Under 1.2 px across, the profile would reach the code bits or what lies beyond a thin
        // quiet zone (an oblique tag's foreshortened edges): that edge is not measured.
        const double clear_px = across * std::min(1.0, quiet_bits);
        if (clear_px < 1.2) continue;
        // Half the clear distance (at least 1 px, at most 4 px) either side of the step. Linear
        // light stretches the bright end: on real prints the quiet zone's shading (paper, glare,
        // the JPEG's ringing) becomes a ramp that pulls a wider profile's centroid outwards;
        // at 0.9 of it (the quadtree boards' reach) the real photos' corners came out ~1.5 px
        // outside the black border (tests/tracking/detect_real_test.cpp).
        const double profile = std::clamp(0.5 * clear_px, 1.0, 4.0);
        const Eigen::Vector2d light = 0.5 * (a + b) - centre_px;
        const double length = (b - a).norm();
        const double margin = std::max(kCornerMarginPx, kCornerMarginFraction * length);
        if (length <= kMaxSpanPx) {
          ok[q][0] = ok[q][1] = fitEdgeLine(patch, a, b, light, profile, margin, line[q][0]);
          line[q][1] = line[q][0];
        } else {
          const Eigen::Vector2d u = (b - a) / length;
          ok[q][0] = fitEdgeLine(patch, a, a + kMaxSpanPx * u, light, profile, margin, line[q][0]);
          ok[q][1] = fitEdgeLine(patch, b - kMaxSpanPx * u, b, light, profile, margin, line[q][1]);
        }
      }
      std::array<Eigen::Vector2d, 4> next = current;
      double moved = 0;
      for (int q = 0; q < 4; ++q) {
        const int before = (q + 3) % 4;  // edge from corner q - 1 to q
        if (!ok[before][1] || !ok[q][0]) continue;
        Eigen::Vector2d corner;
        if (!intersectLines(line[before][1], line[q][0], corner)) continue;
        if ((corner + box_tl - start[q]).norm() > 0.5 * bit_px) continue;  // not this tag's corner
        moved = std::max(moved, (corner - current[q]).norm());
        next[q] = corner;
      }
      current = next;
      if (moved < 0.01) break;
    }
    for (int q = 0; q < 4; ++q) d.corners_px[q] = current[q] + box_tl;
  }

  // image: the rectangle at offset, grey or BGR. At quad_decimate 1 libapriltag 3.3 blurs the
  // image it is given in place (quad_sigma): it gets its own grey copy, so that neither the
  // caller's frame nor the corner refinement sees the blur.
  void run(const cv::Mat& image, const cv::Point& offset, std::vector<TagDetection>& out) {
    if (image.channels() == 3)
      cv::cvtColor(image, search, cv::COLOR_BGR2GRAY);
    else
      image.copyTo(search);
    image_u8_t im{search.cols, search.rows, static_cast<int32_t>(search.step[0]), search.ptr<uint8_t>()};
    Detections dets(apriltag_detector_detect(td, &im));
    for (int k = 0; k < zarray_size(dets.get()); ++k) {
      apriltag_detection_t* det = nullptr;
      zarray_get(dets.get(), k, &det);
      if (det->hamming > options.max_hamming || det->decision_margin < options.min_decision_margin) continue;
      TagDetection d;
      d.family = det->family->name;
      d.id = det->id;
      d.hamming = det->hamming;
      d.decision_margin = det->decision_margin;
      for (int q = 0; q < 4; ++q)
        d.corners_px[q] = Eigen::Vector2d(det->p[q][0] + kApriltagPixelOffset, det->p[q][1] + kApriltagPixelOffset);
      if (options.refine_corners && !det->family->reversed_border) refineCorners(image, *det->family, d);
      for (auto& c : d.corners_px) c += Eigen::Vector2d(offset.x, offset.y);
      out.push_back(d);
    }
  }
};

TagDetector::TagDetector(const DetectorOptions& options) : impl_(std::make_unique<Impl>()) {
  options.validate();
  impl_->options = options;
  impl_->td = apriltag_detector_create();
  for (const std::string& name : options.families) {
    impl_->families.push_back(detail::createFamily(name));
    apriltag_detector_add_family_bits(impl_->td, impl_->families.back().get(), 2);
  }
  impl_->td->quad_decimate = options.decimate;
  impl_->td->quad_sigma = options.sigma;
  impl_->td->nthreads = options.threads;
  impl_->td->refine_edges = options.refine_edges;
  impl_->td->decode_sharpening = options.decode_sharpening;
}

TagDetector::~TagDetector() = default;
TagDetector::TagDetector(TagDetector&&) noexcept = default;
TagDetector& TagDetector::operator=(TagDetector&&) noexcept = default;

const DetectorOptions& TagDetector::options() const { return impl_->options; }

std::vector<TagDetection> TagDetector::detect(const cv::Mat& image) {
  return detect(image, {cv::Rect(0, 0, image.cols, image.rows)});
}

std::vector<TagDetection> TagDetector::detect(const cv::Mat& image, const std::vector<Roi>& rois) {
  if (image.empty()) throw Error("detector: empty image");
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3))
    throw Error("detector: expected an 8-bit grey or BGR image");
  std::vector<TagDetection> found;
  const cv::Rect whole(0, 0, image.cols, image.rows);
  for (const Roi& r : rois) {
    const cv::Rect roi = r & whole;
    if (roi.width < 8 || roi.height < 8) continue;  // nothing a quad fits in
    impl_->run(image(roi), roi.tl(), found);
  }
  if (rois.size() > 1) {
    // One tag found from two overlapping rectangles: keep the stronger decode. Two tags of the
    // same id in one image are both kept (a tag of another set, or a prop's twin): a detection is
    // the same tag only if its centre lies within a quarter of the smaller side of the other's.
    std::vector<TagDetection> unique;
    for (const TagDetection& d : found) {
      const auto same = std::find_if(unique.begin(), unique.end(), [&](const TagDetection& u) {
        return u.family == d.family && u.id == d.id &&
               (centre(u) - centre(d)).norm() < 0.25 * std::min(meanSide(u), meanSide(d));
      });
      if (same == unique.end())
        unique.push_back(d);
      else if (d.decision_margin > same->decision_margin)
        *same = d;
    }
    found.swap(unique);
  }
  return found;
}

}  // namespace previz::tracking
