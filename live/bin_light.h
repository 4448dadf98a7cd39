#pragma once
// Binning a witness plate for the live loop (FrameLoopOptions::witness_bin). A sensor bins light,
// not codes: the mean of the codes is darker than the mean of the light on every mixed pixel of
// bright screen and dark costume, and the key would read them as more foreground than they are
// (a wider silhouette, a hull nearer the camera). Light is taken as code^2 (gamma 2, against
// sRGB's ~2.2: a half-and-half block of codes 150 and 40 gives 110, sRGB's exact mean 112, the
// code mean 95), which keeps it to integer arithmetic that vectorises; a uniform block gives its
// own code back exactly.
#include <opencv2/core.hpp>

namespace previz::live {

// dst (CV_8UC3, 'size') pixel (x, y), each channel: round(sqrt(mean of code^2 over the plate's
// pixels (x * bin + i, y * bin + j), i, j in [0, bin)), the mean rounded to the nearest integer
// first. Plate columns and rows past the edge (a binned size rounded up) repeat the last one.
// src: CV_8UC3 of at least one pixel; 1 <= bin; size: ceil(src / bin) or less (else throws
// Error saying which). dst is reused when it has that size and type. bin 2, the live preview's,
// runs 16 output pixels at a time.
void binLight(const cv::Mat& src, int bin, cv::Size size, cv::Mat& dst);

}  // namespace previz::live
