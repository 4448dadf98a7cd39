// libapriltag behind a small RAII owner: one apriltag_detector_t per TagDetector with every
// family of the props added once.
#include "tracking/detect.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

#include <apriltag/apriltag.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
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
  cv::Mat grey;  // reused conversion buffer
  cv::Mat lut;   // sRGB -> linear, 8 bits (when linear_light)

  ~Impl() {
    if (td) apriltag_detector_destroy(td);  // before the families it references
  }

  void run(const cv::Mat& grey_view, const cv::Point& offset, std::vector<TagDetection>& out) {
    image_u8_t im{grey_view.cols, grey_view.rows, static_cast<int32_t>(grey_view.step[0]),
                  const_cast<uint8_t*>(grey_view.ptr<uint8_t>())};
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
        d.corners_px[q] = Eigen::Vector2d(det->p[q][0] + offset.x + kApriltagPixelOffset,
                                          det->p[q][1] + offset.y + kApriltagPixelOffset);
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
  impl_->lut.create(1, 256, CV_8U);
  for (int i = 0; i < 256; ++i) {
    const double e = i / 255.0;
    const double l = e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4);  // IEC 61966-2-1
    impl_->lut.at<std::uint8_t>(0, i) = static_cast<std::uint8_t>(std::lround(255.0 * l));
  }
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
    const cv::Mat view = image(roi);
    if (image.channels() == 1 && !impl_->options.linear_light) {
      impl_->run(view, roi.tl(), found);
      continue;
    }
    if (image.channels() == 3)
      cv::cvtColor(view, impl_->grey, cv::COLOR_BGR2GRAY);
    else
      view.copyTo(impl_->grey);
    if (impl_->options.linear_light) cv::LUT(impl_->grey, impl_->lut, impl_->grey);
    impl_->run(impl_->grey, roi.tl(), found);
  }
  if (rois.size() > 1) {
    // The same tag from two overlapping rectangles: keep the stronger decode.
    std::map<std::pair<std::string, int>, size_t> best;
    std::vector<TagDetection> unique;
    for (const TagDetection& d : found) {
      const auto key = std::make_pair(d.family, d.id);
      const auto it = best.find(key);
      if (it == best.end()) {
        best[key] = unique.size();
        unique.push_back(d);
      } else if (d.decision_margin > unique[it->second].decision_margin) {
        unique[it->second] = d;
      }
    }
    found.swap(unique);
  }
  return found;
}

}  // namespace previz::tracking
