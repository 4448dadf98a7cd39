#pragma once
// AprilTag detection with libapriltag, one detector per camera (STYLE.md rule 10: the decode
// table of a family is built once, never per frame). Corners come back in OpenCV's pixel
// convention (pixel (0,0) is the centre of the top-left pixel; docs/conventions.md), distorted
// (as seen); the tracker undistorts them with the camera model.
#include <array>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace previz::tracking {

struct DetectorOptions {
  std::vector<std::string> families = {"tag36h11"};
  float decimate = 1.0f;       // libapriltag quad_decimate (>= 1): 2 halves the resolution of the
                               // quad search (4x faster) and loses tags under ~40 px
  // quad_sigma: Gaussian blur of the image the quads are searched in (decoding and edge refinement
  // use the sharp image). 0.8 by default: on a camera with 2 grey levels of noise the unblurred
  // search segments the noise itself and is ~7x slower for the same tags.
  float sigma = 0.8f;
  int threads = 1;             // libapriltag worker threads per call (the tracker runs cameras in parallel)
  bool refine_edges = true;    // fit each edge to the image gradient (sub-pixel corners)
  double decode_sharpening = 0.25;
  // 8-bit input is sRGB-encoded (the studio renderer and most video cameras): the tag is searched
  // on the decoded, linear image (8-bit LUT). On the encoded values a black/white edge's profile is
  // asymmetric and libapriltag's edges sit ~0.2 px inside the black border: a 40 px tag looks 1 %
  // small, which is 1 % of the distance for a camera tracked from one plane of studio tags
  // (calib's DetectOptions::linear_light, same reason). Set false for linear cameras.
  bool linear_light = true;
  int max_hamming = 1;         // bit errors accepted when decoding (the family table holds up to 2)
  float min_decision_margin = 20.0f;  // reject weaker decodes (false positives in noise)
  void validate() const;       // throws Error naming the field
};

struct TagDetection {
  std::string family;
  int id = 0;
  // p[0..3] of libapriltag (bottom-left, bottom-right, top-right, top-left as read), in OpenCV's
  // pixel convention of the full image (ROI offsets added).
  std::array<Eigen::Vector2d, 4> corners_px;
  int hamming = 0;
  float decision_margin = 0;
};

// A rectangle of the image to search (pixels, clipped to the image by detect()).
using Roi = cv::Rect;

class TagDetector {
 public:
  explicit TagDetector(const DetectorOptions& options);  // throws Error naming a bad option
  ~TagDetector();
  TagDetector(TagDetector&&) noexcept;
  TagDetector& operator=(TagDetector&&) noexcept;

  // Full image; 'image' is 8-bit grey or BGR (converted here).
  std::vector<TagDetection> detect(const cv::Mat& image);
  // Only inside the given rectangles (each searched on its own; a tag found in two overlapping
  // rectangles is returned once). Only the pixels inside a rectangle are converted to grey.
  std::vector<TagDetection> detect(const cv::Mat& image, const std::vector<Roi>& rois);

  const DetectorOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::tracking
