#pragma once
// libapriltag's Gaussian blur of the quad search (image_u8_gaussian_blur, which
// apriltag_detector_detect applies at quad_decimate 1 when quad_sigma > 0, in place on the image it
// decodes and refines the edges on), computed here with the same integers: the same kernel (its
// size from quad_sigma as libapriltag sizes it, 8-bit weights), the same rows and columns left
// as they are at the borders, the same rounding. libapriltag's own loop is scalar and walks each
// column one pixel at a time (a third of the detector's time on the live bench take); this one
// works along rows, 8-16 pixels at a time. The detector blurs with it and hands libapriltag
// quad_sigma 0: the same detections, bit for bit (tests/tracking/apriltag_blur_test.cpp). Internal to
// tracking.
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace previz::tracking::detail {

// libapriltag's kernel size for quad_sigma (odd; 1 = no blur).
int apriltagBlurSize(float quad_sigma);

// The blur's buffers, kept by the caller from call to call (a detector searches rectangles of
// every size, frame after frame: no allocation once they have grown).
struct ApriltagBlurScratch {
  std::vector<std::uint8_t> rows;  // the row-blurred image
  std::vector<std::uint16_t> acc;  // one row's sums
  std::vector<const std::uint8_t*> src;
};

// Blurs 'grey' (CV_8UC1) in place as libapriltag 3.3 would for quad_sigma. False, and 'grey'
// untouched, where libapriltag would not blur (quad_sigma <= 0, kernel size 1) or where the image
// is not larger than the kernel (there libapriltag writes outside its row buffer): leave those
// to libapriltag.
bool apriltagBlur(cv::Mat& grey, float quad_sigma, ApriltagBlurScratch& scratch);

}  // namespace previz::tracking::detail
