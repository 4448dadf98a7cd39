// libapriltag behind a small RAII owner: one apriltag_detector_t per TagDetector with every
// family of the props added once.
#include "tracking/detect.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <sstream>
#include <vector>

#include <Eigen/Dense>

#include <apriltag/apriltag.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/marker_edges.h"
#include "core/srgb.h"
#include "tracking/detail/apriltag_blur.h"
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
// than kMaxSpanPx may be fitted as a parabola (the lens bends them: over 40 px at k1 = -0.22,
// ~0.06 px). Before, such edges were fitted over 40 px near each end with the margin of the whole
// edge, which left nothing to fit on tags over ~190 px: those were never refined.
constexpr int kRefinePasses = 2;
constexpr double kCornerMarginPx = 3.0, kCornerMarginFraction = 0.1, kMaxSpanPx = 40.0;
// The response's shift of a tag's edges (TagDetector::Impl::refineCorners): measured on the
// border's inner edge from at least kMinInnerPoints points, on tags whose bits are kMinShiftBitPx
// or more (smaller: the next bit's edge is within the step profile's reach; the studio's 2-4 px
// bits read -0.03 px on an sRGB camera decoded as sRGB, which would cost 0.24 % of the distance).
// A tag's own is used when its standard error is at most kOwnShiftSe px (a 0.02 px shift of every
// edge is 0.1 % of a 40 px tag's size, 4 mm at 4 m); otherwise the shift pooled over the tags of
// the call (inverse-variance weights, standard errors floored at kMinShiftSe, from 0 - the
// declared response - with the weight kPriorShiftWeight). Nothing is carried from call to call.
constexpr int kMinInnerPoints = 6;
constexpr double kMinShiftBitPx = 6.0;
constexpr double kOwnShiftSe = 0.01, kMinShiftSe = 0.003, kPriorShiftWeight = 1.0 / (0.1 * 0.1);
// sigmaForNoise: no blur under kNoiseForBlur grey levels of noise in the grey image; above,
// kBlurPerNoise x the noise (the studio's witnesses, 2 levels a channel = 1.3 in the grey: 0.8,
// the blur the fixed default was tuned to), at most kMaxAutoSigma.
constexpr double kNoiseForBlur = 0.8, kBlurPerNoise = 0.62, kMaxAutoSigma = 1.6;

// A tag's outer edge from corner a to corner b: its distance inwards from the chord,
// s(t) = c0 + c1 t + c2 t^2 at t along it (a = 0, b = 1 chord length), least squares through the
// measured points.
struct EdgeCurve {
  Eigen::Vector2d a, u, in;  // start, unit chord, unit normal towards the tag's centre
  double length = 0, c0 = 0, c1 = 0, c2 = 0;

  bool fit(const Eigen::Vector2d& from, const Eigen::Vector2d& to, const Eigen::Vector2d& centre,
           const std::vector<Eigen::Vector2d>& points, bool bent) {
    a = from;
    length = (to - from).norm();
    u = (to - from) / length;
    in = Eigen::Vector2d(-u.y(), u.x());
    if (in.dot(centre - from) < 0) in = -in;
    // A line; a parabola when the edge may be bent and its curvature is significant (over 3 of
    // its standard errors): the parabola's end tangents are noisier than the line's.
    auto solve = [&](int terms, Eigen::VectorXd& c, double& se_last) {
      if (static_cast<int>(points.size()) < terms + 2) return false;
      Eigen::MatrixXd A(points.size(), terms);
      Eigen::VectorXd y(points.size());
      for (size_t k = 0; k < points.size(); ++k) {
        const double t = (points[k] - a).dot(u) / length;
        const auto row = static_cast<Eigen::Index>(k);
        A(row, 0) = 1;
        A(row, 1) = t;
        if (terms == 3) A(row, 2) = t * t;
        y(row) = (points[k] - a).dot(in);
      }
      const Eigen::MatrixXd AtA = A.transpose() * A;
      c = AtA.ldlt().solve(A.transpose() * y);
      const double dof = static_cast<double>(points.size()) - terms;
      const double var = (y - A * c).squaredNorm() / dof;
      se_last = std::sqrt(var * AtA.inverse()(terms - 1, terms - 1));
      return c.allFinite();
    };
    Eigen::VectorXd c;
    double se = 0;
    if (!solve(2, c, se)) return false;
    c0 = c(0);
    c1 = c(1);
    c2 = 0;
    if (bent && solve(3, c, se) && std::abs(c(2)) > 3 * se) {
      c0 = c(0);
      c1 = c(1);
      c2 = c(2);
    }
    return true;
  }
  // How far inwards of the edge p lies (px).
  double inwards(const Eigen::Vector2d& p) const {
    const double t = (p - a).dot(u) / length;
    return (p - a).dot(in) - (c0 + c1 * t + c2 * t * t);
  }
  // The tangent at t as a line n . x = c (n unit).
  Eigen::Vector3d tangent(double t) const {
    const Eigen::Vector2d p = a + t * length * u + (c0 + c1 * t + c2 * t * t) * in;
    const Eigen::Vector2d dir = length * u + (c1 + 2 * c2 * t) * in;
    const Eigen::Vector2d n = Eigen::Vector2d(-dir.y(), dir.x()).normalized();
    return Eigen::Vector3d(n.x(), n.y(), n.dot(p));
  }
};

// One tag's refinement: its four outer edges as measured (the response's shift not taken out)
// in the patch's pixels, and the shift its own inner edge says, with its standard error.
struct TagFit {
  bool ok = false;
  std::array<EdgeCurve, 4> curve;
  Eigen::Vector2d box_tl = Eigen::Vector2d::Zero();  // patch -> image
  std::array<Eigen::Vector2d, 4> start;              // libapriltag's corners, image
  double bit_px = 0;
  int inner_points = 0;
  double own_shift = 0, own_se = 0;

  // The corners (patch pixels) with every outer edge moved inwards by shift; false (why says
  // why) when two edges are near parallel or a corner is more than half a bit from libapriltag's.
  bool cornersAt(double shift, std::array<Eigen::Vector2d, 4>& out, std::string& why) const {
    std::array<EdgeCurve, 4> moved = curve;
    for (EdgeCurve& c : moved) c.c0 += shift;
    for (int q = 0; q < 4; ++q) {
      if (!intersectLines(moved[(q + 3) % 4].tangent(1.0), moved[q].tangent(0.0), out[q])) {
        why = "two edges near parallel";
        return false;
      }
      if ((out[q] + box_tl - start[q]).norm() > 0.5 * bit_px) {
        why = "a corner more than half a bit from the detector's";
        return false;
      }
    }
    return true;
  }
};

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

double estimateNoise(const cv::Mat& image, const cv::Rect& rect) {
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3))
    throw Error("estimateNoise: expected an 8-bit grey or BGR image");
  const cv::Rect r = rect & cv::Rect(1, 1, image.cols - 2, image.rows - 2);
  if (r.width <= 0 || r.height <= 0) return 0;
  // Every other pixel of every other row; every 4th of every 4th on large rectangles (still
  // ~50 000 samples on a 1280 x 720 frame).
  const int step = r.area() > 200000 ? 4 : 2;
  const int channels = image.channels();
  // The grey libapriltag sees (OpenCV's BGR2GRAY weights, in 1/256), x 256.
  auto grey = [&](const std::uint8_t* row, int u) {
    if (channels == 1) return 256 * static_cast<int>(row[u]);
    const std::uint8_t* p = row + 3 * u;
    return 29 * p[0] + 150 * p[1] + 77 * p[2];
  };
  // |response| of the 3 x 3 mask [1 -2 1; -2 4 -2; 1 -2 1] (sum of squares 36: 6 sigma for white
  // noise), in 1/16 grey level, as a histogram for the median.
  std::vector<int> histogram(16 * 16 * 255 + 1, 0);
  long count = 0;
  for (int v = r.y; v < r.y + r.height; v += step) {
    const std::uint8_t* a = image.ptr<std::uint8_t>(v - 1);
    const std::uint8_t* b = image.ptr<std::uint8_t>(v);
    const std::uint8_t* c = image.ptr<std::uint8_t>(v + 1);
    for (int u = r.x; u < r.x + r.width; u += step) {
      const int m = grey(a, u - 1) - 2 * grey(a, u) + grey(a, u + 1) -
                    2 * (grey(b, u - 1) - 2 * grey(b, u) + grey(b, u + 1)) + grey(c, u - 1) - 2 * grey(c, u) +
                    grey(c, u + 1);
      ++histogram[static_cast<size_t>(std::abs(m) / 16)];
      ++count;
    }
  }
  long seen = 0;
  size_t median = 0;
  while (median + 1 < histogram.size() && (seen += histogram[median]) * 2 < count) ++median;
  // median |N(0, 6 sigma)| = 0.6745 x 6 sigma; the bin's centre, in grey levels
  return (static_cast<double>(median) + 0.5) / 16.0 / (6.0 * 0.6745);
}

float sigmaForNoise(double noise) {
  if (!(noise >= kNoiseForBlur)) return 0.0f;
  return static_cast<float>(std::min(kBlurPerNoise * noise, kMaxAutoSigma));
}

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
  detail::ApriltagBlurScratch blur_scratch;  // apriltagBlur's buffers
  cv::Mat grey8;   // around one tag, grey from the caller's image (refine_corners)
  cv::Mat patch;   // the same, float, linear light
  std::vector<std::pair<size_t, TagFit>> fits;  // this call's refined tags (index into its detections)
  double last_noise = -1;
  float last_sigma = 0;
  double camera_noise = -1;  // measured on the last search of the whole frame
  // The same families without libapriltag's edge refinement, for the second pass on clean frames.
  apriltag_detector_t* td_plain = nullptr;
  size_t last_run_first = 0;

  ~Impl() {
    if (td) apriltag_detector_destroy(td);  // before the families it references
    if (td_plain) apriltag_detector_destroy(td_plain);
  }

  // d.corners_px in image's pixels (image: the rectangle searched, grey or BGR). Each of the
  // tag's four outer edges (black border -> white quiet zone) is fitted as a line (the centroid
  // of its dark -> light step, core/marker_edges.h) on a float patch around the tag, decoded to
  // linear light when the camera is sRGB (DetectorOptions::linear_light), and each corner is
  // where its two edges meet.
  //
  // A camera's tone response is not known here (sRGB, a 2.2 power, Rec.709, a filmic curve, or
  // linear), and decoding with the wrong one moves every edge's step centroid towards the light
  // side (or the dark side) by the same few tenths of a pixel: an outer edge outwards, and the
  // tag looks larger (tests/tracking/near_frontal_test.cpp: a linear camera decoded as sRGB put
  // the corners 0.7 px out, 0.7 mm at 0.2 m). The black border is also measured from inside,
  // where a white data bit borders it (that edge's light side is inwards): the same response
  // moves it inwards, so the border bit, predicted one bit wide by the outer edges' own square,
  // measures 2 b (1 - 1/width_at_border) too wide for a shift b. b is solved per tag (or pooled
  // over the call's tags where a tag's own is not precise: kOwnShiftSe) and every outer edge
  // moved back by it: the corners then no longer depend on the response (to first order; the blur
  // is symmetric). Per tag, all or nothing: the refined corners replace libapriltag's only when
  // all four outer edges were measured and every corner stays within half a bit of libapriltag's
  // (otherwise the fit is on something else: a neighbour, a shadow's edge); otherwise
  // libapriltag's corners are kept and TagDetection::refine_why_not says why. Returns the fit
  // (ok: refined) for finishRefinement, which sets the corners.
  TagFit refineCorners(const cv::Mat& image, const apriltag_family_t& family, TagDetection& d) {
    TagFit fit;
    const std::array<Eigen::Vector2d, 4> start = d.corners_px;
    double side = 0;
    Eigen::Vector2d lo = start[0], hi = start[0];
    for (int q = 0; q < 4; ++q) {
      const double e = (start[(q + 1) % 4] - start[q]).norm();
      side += 0.25 * e;
      lo = lo.cwiseMin(start[q]);
      hi = hi.cwiseMax(start[q]);
    }
    const int B = family.width_at_border;
    const double bit_px = side / B;
    const double quiet_bits = 0.5 * (family.total_width - family.width_at_border);
    const int margin = 8;  // the profile's reach (4 px) and the 2 x 2 interpolation, with room
    const cv::Rect box = cv::Rect(cv::Point(static_cast<int>(std::floor(lo.x())) - margin,
                                            static_cast<int>(std::floor(lo.y())) - margin),
                                  cv::Point(static_cast<int>(std::ceil(hi.x())) + margin + 1,
                                            static_cast<int>(std::ceil(hi.y())) + margin + 1)) &
                         cv::Rect(0, 0, image.cols, image.rows);
    d.refined = false;
    d.refine_why_not = "tag at the image's border";
    if (box.width < 4 || box.height < 4) return fit;
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
    // The tag's plane in bits: the black border's outer square is [0, B]^2, corner q at
    // kSquare[q] B (libapriltag's p[0..3] go around the tag, so any assignment that goes around
    // it is a homography of the same quad).
    static const Eigen::Vector2d kSquare[4] = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
    const Eigen::Vector2d box_tl(box.x, box.y);
    const Eigen::Vector2d centre_bits(0.5 * B, 0.5 * B);
    fit.box_tl = box_tl;
    fit.start = start;
    fit.bit_px = bit_px;
    auto homographyOf = [&](const std::array<Eigen::Vector2d, 4>& corners) {
      cv::Point2f from[4], to[4];
      for (int q = 0; q < 4; ++q) {
        from[q] = cv::Point2f(static_cast<float>(B * kSquare[q].x()), static_cast<float>(B * kSquare[q].y()));
        to[q] = cv::Point2f(static_cast<float>(corners[q].x()), static_cast<float>(corners[q].y()));
      }
      cv::Mat Hcv;
      cv::getPerspectiveTransform(from, to).convertTo(Hcv, CV_64F);
      Eigen::Matrix3d H;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) H(r, c) = Hcv.at<double>(r, c);
      return H;
    };
    std::array<Eigen::Vector2d, 4> current;
    for (int q = 0; q < 4; ++q) current[q] = start[q] - box_tl;
    std::vector<Eigen::Vector2d> points;
    for (int pass = 0; pass < kRefinePasses; ++pass) {
      const Eigen::Matrix3d H = homographyOf(current);
      const Eigen::Vector2d centre_px = homography(H, centre_bits);
      // Outer edge q runs from corner q to corner q + 1, measured along its whole length and
      // fitted as a parabola across the chord (a line up to kMaxSpanPx: the lens bends longer
      // edges, over 40 px at k1 = -0.22 by ~0.06 px); its corners where the tangents at the ends
      // meet.
      std::array<EdgeCurve, 4> curve;
      std::array<double, 4> reach{};
      for (int q = 0; q < 4; ++q) {
        const Eigen::Vector2d& a = current[q];
        const Eigen::Vector2d& b = current[(q + 1) % 4];
        const Eigen::Vector2d mid_bits = 0.5 * B * (kSquare[q] + kSquare[(q + 1) % 4]);
        const Eigen::Vector2d inward = (centre_bits - mid_bits).normalized();
        const double across = (homography(H, mid_bits + inward) - homography(H, mid_bits)).norm();
        // Under 1.2 px across, the profile would reach the code bits or what lies beyond a thin
        // quiet zone (an oblique tag's foreshortened edges): the tag is not refined.
        const double clear_px = across * std::min(1.0, quiet_bits);
        if (clear_px < 1.2) {
          d.refine_why_not = "an edge under 1.2 px a bit";
          return fit;
        }
        // Half the clear distance (at least 1 px, at most 4 px) either side of the step. Linear
        // light stretches the bright end: on real prints the quiet zone's shading (paper, glare,
        // the JPEG's ringing) becomes a ramp that pulls a wider profile's centroid outwards;
        // at 0.9 of it (the quadtree boards' reach) the real photos' corners came out ~1.5 px
        // outside the black border (tests/tracking/detect_real_test.cpp).
        reach[q] = std::clamp(0.5 * clear_px, 1.0, 4.0);
        const double length = (b - a).norm();
        const double corner_margin = std::max(kCornerMarginPx, kCornerMarginFraction * length);
        if (!measureEdgePoints(patch, a, b, 0.5 * (a + b) - centre_px, reach[q], corner_margin, points) ||
            !curve[q].fit(a, b, centre_px, points, length > kMaxSpanPx)) {
          d.refine_why_not = "an outer edge not measured";
          return fit;
        }
      }
      // The quad of the measured outer edges (before the response's shift is taken out).
      std::array<Eigen::Vector2d, 4> measured;
      for (int q = 0; q < 4; ++q)
        if (!intersectLines(curve[(q + 3) % 4].tangent(1.0), curve[q].tangent(0.0), measured[q])) {
          d.refine_why_not = "two edges near parallel";
          return fit;
        }
      const Eigen::Matrix3d Hm = homographyOf(measured);
      const Eigen::Matrix3d Hm_inv = Hm.inverse();
      const Eigen::Vector2d centre_m = homography(Hm, centre_bits);
      // Black and white as this tag shows them: border bits' and quiet zone's centres.
      std::vector<float> dark, light;
      for (int q = 0; q < 4; ++q) {
        const Eigen::Vector2d s0 = B * kSquare[q], along = B * (kSquare[(q + 1) % 4] - kSquare[q]) / B;
        const Eigen::Vector2d inward = (centre_bits - (s0 + 0.5 * B * along)).normalized();
        for (int k = 0; k < B; ++k) {
          const Eigen::Vector2d on = s0 + (k + 0.5) * along;
          const Eigen::Vector2d in = homography(Hm, on + 0.5 * inward), out = homography(Hm, on - 0.5 * inward);
          const float vi = bilinearAt(patch, in.x(), in.y()), vo = bilinearAt(patch, out.x(), out.y());
          if (std::isfinite(vi)) dark.push_back(vi);
          if (std::isfinite(vo)) light.push_back(vo);
        }
      }
      if (dark.empty() || light.empty()) {
        d.refine_why_not = "tag at the image's border";
        return fit;
      }
      auto median = [](std::vector<float>& v) {
        std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
        return v[v.size() / 2];
      };
      const float threshold = 0.5f * (median(dark) + median(light));
      // The border's inner edge along each run of white data bits next to it: how much further in
      // it lies than one bit from the measured outer line near it.
      double sum = 0, sum2 = 0;
      int count = 0;
      for (int q = 0; q < 4; ++q) {
        const Eigen::Vector2d s0 = B * kSquare[q], along = B * (kSquare[(q + 1) % 4] - kSquare[q]) / B;
        const Eigen::Vector2d inward = (centre_bits - (s0 + 0.5 * B * along)).normalized();
        for (int k = 1; k < B - 1;) {
          auto white = [&](int cell) {
            const Eigen::Vector2d c = homography(Hm, s0 + (cell + 0.5) * along + 1.5 * inward);
            return bilinearAt(patch, c.x(), c.y()) > threshold;
          };
          if (!white(k)) {
            ++k;
            continue;
          }
          int end = k + 1;
          while (end < B - 1 && white(end)) ++end;
          const Eigen::Vector2d from = homography(Hm, s0 + k * along + inward);
          const Eigen::Vector2d to = homography(Hm, s0 + end * along + inward);
          k = end;
          // Clear of the neighbouring black bits' blur at the run's ends.
          const double run_margin = std::max(2.0, 0.25 * bit_px);
          if (!measureEdgePoints(patch, from, to, centre_m - 0.5 * (from + to), reach[q], run_margin, points) &&
              points.empty())
            continue;
          for (const Eigen::Vector2d& p : points) {
            const Eigen::Vector2d p_bits = homography(Hm_inv, p);
            const double bit_here = (homography(Hm, p_bits) - homography(Hm, p_bits - inward)).norm();
            const double e = curve[q].inwards(p) - bit_here;
            sum += e;
            sum2 += e * e;
            ++count;
          }
        }
      }
      // The tag's own shift and its standard error (measured on bits of kMinShiftBitPx or more:
      // on smaller bits the next bit's edge is within the profile's reach); 0 (the declared
      // response) for this pass when it is not precise, the shift pooled over the call's tags in
      // the end (finishRefinement).
      fit.inner_points = count;
      fit.own_shift = 0;
      fit.own_se = std::numeric_limits<double>::infinity();
      const double to_shift = 1.0 / (2.0 * (1.0 - 1.0 / B));
      if (count >= kMinInnerPoints && bit_px >= kMinShiftBitPx) {
        const double mean = sum / count;
        const double var = std::max(sum2 / count - mean * mean, 0.0);
        fit.own_shift = mean * to_shift;
        fit.own_se = std::sqrt(var / (count - 1)) * to_shift;
        fit.own_se = std::max(fit.own_se, kMinShiftSe);
      }
      const double shift = fit.own_se <= kOwnShiftSe ? fit.own_shift : 0.0;
      for (int q = 0; q < 4; ++q) fit.curve[q] = curve[q];
      std::array<Eigen::Vector2d, 4> next;
      if (!fit.cornersAt(shift, next, d.refine_why_not)) return fit;
      double moved = 0;
      for (int q = 0; q < 4; ++q) moved = std::max(moved, (next[q] - current[q]).norm());
      current = next;
      if (moved < 0.01) break;
    }
    fit.ok = true;
    return fit;
  }

  // image: the rectangle at offset, grey or BGR. At quad_decimate 1 libapriltag 3.3 blurs the
  // image it is given in place (quad_sigma): it gets its own grey copy, so that neither the
  // caller's frame nor the corner refinement sees the blur.
  // With 'second' (td_plain, after td on the same rectangle): only the tags td did not find there.
  void run(const cv::Mat& image, const cv::Point& offset, std::vector<TagDetection>& out, bool second = false) {
    const size_t first = out.size();
    const size_t before = second ? last_run_first : out.size();
    last_run_first = out.size();
    // The second pass runs only where the first searched without blur, which leaves 'search'
    // as it converted it: the same grey, not converted again.
    if (!second) {
      if (image.channels() == 3)
        cv::cvtColor(image, search, cv::COLOR_BGR2GRAY);
      else
        image.copyTo(search);
    }
    // libapriltag's blur at decimate 1 done here, the same bits (detail/apriltag_blur.h); it is
    // then told not to blur. Where this does not apply, libapriltag blurs as before.
    apriltag_detector_t* const detector = second ? td_plain : td;
    const float quad_sigma = detector->quad_sigma;
    if (!second && !options.library_blur && detector->quad_decimate == 1.0f &&
        detail::apriltagBlur(search, quad_sigma, blur_scratch))
      detector->quad_sigma = 0;
    image_u8_t im{search.cols, search.rows, static_cast<int32_t>(search.step[0]), search.ptr<uint8_t>()};
    Detections dets(apriltag_detector_detect(detector, &im));
    detector->quad_sigma = quad_sigma;
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
      if (second) {
        const Eigen::Vector2d at = centre(d) + Eigen::Vector2d(offset.x, offset.y);
        bool known = false;
        for (size_t j = before; j < first && !known; ++j)
          known = out[j].family == d.family && out[j].id == d.id &&
                  (centre(out[j]) - at).norm() < 0.25 * std::min(meanSide(out[j]), meanSide(d));
        if (known) continue;
      }
      if (options.refine_corners && !det->family->reversed_border) {
        TagFit fit = refineCorners(image, *det->family, d);
        if (fit.ok) fits.emplace_back(out.size(), std::move(fit));
      }
      const Eigen::Vector2d shift_to_image(offset.x, offset.y);
      for (auto& c : d.corners_px) c += shift_to_image;
      if (!fits.empty() && fits.back().first == out.size()) {
        fits.back().second.box_tl += shift_to_image;
        for (auto& c : fits.back().second.start) c += shift_to_image;
      }
      out.push_back(d);
    }
  }

  // The shift pooled over this call's tags (those with a precise own shift and the rest alike;
  // from 0, the declared response, at kPriorShiftWeight); each tag's corners at its own shift
  // when precise, else at the pooled one.
  void finishRefinement(std::vector<TagDetection>& out) {
    double w_sum = kPriorShiftWeight, ws_sum = 0;
    for (const auto& [index, fit] : fits)
      if (fit.inner_points >= kMinInnerPoints) {
        const double w = 1.0 / (fit.own_se * fit.own_se);
        w_sum += w;
        ws_sum += w * fit.own_shift;
      }
    const double pooled = ws_sum / w_sum;
    for (auto& [index, fit] : fits) {
      TagDetection& d = out[index];
      const double shift = fit.own_se <= kOwnShiftSe ? fit.own_shift : pooled;
      std::array<Eigen::Vector2d, 4> corners;
      if (!fit.cornersAt(shift, corners, d.refine_why_not)) continue;
      for (int q = 0; q < 4; ++q) d.corners_px[q] = corners[q] + fit.box_tl;
      d.refined = true;
      d.refine_why_not.clear();
      d.response_shift_px = shift;
    }
    fits.clear();
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
  if (options.auto_sigma && options.refine_edges) {
    impl_->td_plain = apriltag_detector_create();
    for (const auto& family : impl_->families) apriltag_detector_add_family_bits(impl_->td_plain, family.get(), 2);
    impl_->td_plain->quad_decimate = options.decimate;
    impl_->td_plain->quad_sigma = 0;
    impl_->td_plain->nthreads = options.threads;
    impl_->td_plain->refine_edges = false;
    impl_->td_plain->decode_sharpening = options.decode_sharpening;
  }
}

TagDetector::~TagDetector() = default;
TagDetector::TagDetector(TagDetector&&) noexcept = default;
TagDetector& TagDetector::operator=(TagDetector&&) noexcept = default;

const DetectorOptions& TagDetector::options() const { return impl_->options; }
double TagDetector::lastNoise() const { return impl_->last_noise; }
float TagDetector::lastSigma() const { return impl_->last_sigma; }

std::vector<TagDetection> TagDetector::detect(const cv::Mat& image) {
  return detect(image, {cv::Rect(0, 0, image.cols, image.rows)});
}

std::vector<TagDetection> TagDetector::detect(const cv::Mat& image, const std::vector<Roi>& rois) {
  if (image.empty()) throw Error("detector: empty image");
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3))
    throw Error("detector: expected an 8-bit grey or BGR image");
  std::vector<TagDetection> found;
  const cv::Rect whole(0, 0, image.cols, image.rows);
  impl_->last_sigma = impl_->options.sigma;
  impl_->last_noise = -1;
  if (impl_->options.auto_sigma) {
    // The noise of the grey libapriltag searches, measured on the whole frame when it is searched
    // whole (or on the camera's first call): rectangles around tags are mostly the tags' edges,
    // which the estimator would count as noise; they use the camera's last measure.
    bool whole_searched = false;
    for (const Roi& r : rois) whole_searched |= (r & whole) == whole;
    if (whole_searched || impl_->camera_noise < 0) impl_->camera_noise = estimateNoise(image, whole);
    impl_->last_noise = impl_->camera_noise;
    impl_->last_sigma = sigmaForNoise(impl_->last_noise);
  }
  impl_->td->quad_sigma = impl_->last_sigma;
  // Clean frames (no blur chosen) are searched a second time without libapriltag's edge
  // refinement: it moves the edges of tags of ~13 px before decoding them, and they are lost
  // (../shared/data/apriltag-real: 1 of 47); the tags only that pass finds are added.
  const bool second_pass = impl_->td_plain && impl_->last_sigma == 0.0f;
  for (const Roi& r : rois) {
    const cv::Rect roi = r & whole;
    if (roi.width < 8 || roi.height < 8) continue;  // nothing a quad fits in
    impl_->run(image(roi), roi.tl(), found);
    if (second_pass) impl_->run(image(roi), roi.tl(), found, true);
  }
  impl_->finishRefinement(found);
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
