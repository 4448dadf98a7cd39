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
  // quad_sigma: Gaussian blur of the image the quads are searched in. At decimate 1 libapriltag
  // 3.3 blurs the one image it also decodes and refines the edges on (in place: the detector
  // hands it a copy); at decimate > 1 those use the sharp image. 0.8 by default: on a camera with
  // 2 grey levels of noise the unblurred search segments the noise itself and is ~7x slower for
  // the same tags.
  float sigma = 0.8f;
  // auto_sigma: quad_sigma chosen on every call from the image's own noise (estimateNoise, over
  // the rectangles searched) instead of 'sigma': sigmaForNoise. On the studio's witnesses (noise
  // 2 grey levels a channel) that is 0.8 as before; on clean footage, JPEG photos and a good
  // camera's frames 0, which finds the small tags the blur loses.
  bool auto_sigma = true;
  // The blur at decimate 1 computed by previz with libapriltag's own integers, 8-16 pixels at a
  // time (tracking/detail/apriltag_blur.h), libapriltag then handed quad_sigma 0: the same
  // detections. true = libapriltag blurs (its scalar code; to compare).
  bool library_blur = false;
  int threads = 1;             // libapriltag worker threads per call (the tracker runs cameras in parallel)
  bool refine_edges = true;    // fit each edge to the image gradient (sub-pixel corners)
  double decode_sharpening = 0.25;
  // Each corner refined from the tag's two edges through it (core/marker_edges.h: the centroid
  // of each edge's dark -> light step, lines through them, their intersection) on a float,
  // linear-light patch around the tag. libapriltag's own corners come from the 8-bit values,
  // where a black/white edge's profile is asymmetric (sRGB): they sit ~0.2 px inside the black
  // border, and a 40 px tag looks 1 % small, which is 1 % of the distance for a camera tracked
  // from one plane of studio tags. A corner whose edges cannot be measured (too short, at the
  // image's border, no quiet zone) keeps libapriltag's. Families with a reversed border
  // (tagStandard41h12, tagCircle*) keep libapriltag's corners.
  bool refine_corners = true;
  // 8-bit input is sRGB-encoded (the studio renderer and most video cameras): the corner
  // refinement decodes it to linear light. The tags are searched and decoded on the 8-bit values
  // as they are: an 8-bit linear image has too few levels in the shadows (on the real outdoor
  // photos of tests/tracking/detect_real_test.cpp it lost 37 of 47 tags). Set false for linear
  // cameras.
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
  // With DetectorOptions::refine_corners: whether corners_px are previz's refined corners (else
  // libapriltag's, and refine_why_not says why), and the tone response's shift of the tag's edges
  // that the refinement measured and took out (px, towards the light side; 0 for an sRGB camera
  // decoded as sRGB).
  bool refined = false;
  std::string refine_why_not;
  double response_shift_px = 0;
};

// The standard deviation (grey levels) of the noise of an 8-bit image's grey (a BGR image's grey as
// libapriltag gets it): Immerkaer's Laplacian-difference estimator (J. Immerkaer, "Fast noise
// variance estimation", CVIU 1996) with the median of |response| instead of its mean, so that
// edges and texture (a minority of the pixels) do not count as noise; sampled inside rect
// (clipped to the image).
double estimateNoise(const cv::Mat& image, const cv::Rect& rect);
// The quad search's blur for that noise: 0 under 0.8 grey levels (clean footage, JPEG photos,
// whose compression removes the sensor's noise from flat areas: the real photos of
// ../shared/data/apriltag-real measure 0.5), 0.62 x noise above (the studio's witnesses, 2 levels
// a channel, 1.3 in the grey: 0.8, the blur the fixed default was tuned to), at most 1.6.
float sigmaForNoise(double noise);

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
  // rectangles is returned once, two tags of the same id both). Only the pixels inside a
  // rectangle are converted to grey.
  std::vector<TagDetection> detect(const cv::Mat& image, const std::vector<Roi>& rois);

  const DetectorOptions& options() const;
  // With auto_sigma: the noise measured on the last call and the blur it chose (else -1 and sigma).
  double lastNoise() const;
  float lastSigma() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::tracking
