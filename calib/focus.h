#pragma once
// Focus of calibration views: how sharp the board is in each image, and which views of a
// sequence are too soft to use. Soft views are judged against the sequence itself (no absolute
// threshold): the same lens, light and board give the same sharpness when in focus.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "calib/observations.h"

namespace previz::calib {

// Measures over the board region: the convex hull of 'points' (the whole image when empty).
// image: 8-bit grey, BGR or BGRA (throws Error otherwise).
//  - modified_laplacian: Nayar's modified Laplacian |2I - I(x-1) - I(x+1)| + |2I - I(y-1) -
//    I(y+1)|, mean over the region, grey levels (0..255).
//  - variance_of_laplacian: variance of the 4-neighbour Laplacian over the region (Pech-Pacheco
//    et al. 2000), grey levels squared.
//  Both grow with the board's contrast and with the number of edges per pixel (a board far away
//  looks "sharper"), so they only compare views of one board at one distance. Hence:
//  - sharpness: on the region's edge pixels (gradient above a quarter of its 99th percentile),
//    sum of the modified Laplacian (less the region's noise floor, its median on flat pixels)
//    over the sum of the gradient magnitude. For an edge blurred by sigma px both sums scale
//    with the contrast and the edge length, and their ratio is about 0.8 / sigma (the integral
//    of |I''| across an edge is twice the peak of I', the integral of |I'| is the contrast), so it
//    depends neither on the contrast nor on the board's apparent size. 2 for a step between
//    two pixels; 1.35-1.5 on the studio's in-focus renders at any distance and tilt, 0.16-0.26
//    with a defocus of sigma 2.5-4 px (tests/calib/focus_test.cpp). Computed in linear light
//    when linear_light (sRGB input).
FocusMeasure measureFocus(const cv::Mat& image, const std::vector<Observation>& points,
                          bool linear_light = true);

struct FocusOptions {
  // A view is soft when its sharpness is below this fraction of the sequence's reference (the
  // median of the sharper half of the found views). Sharpness ~ 0.8 / edge sigma, so 0.4
  // rejects views whose edges are 2.5 times as wide as those of the well-focused ones: on the
  // studio's renders (in focus ~0.55 px) a defocus sigma above ~1.3 px; the test sequences sit
  // at 0.16-0.26 (sigma 2.5-4 px, rejected) against 1.35-1.5 (kept), a factor 2 either side of
  // the limit. Blur of that size also costs corner accuracy (AprilGrid tag corners at 1 px
  // defocus and noise 2: median 0.08 px; at 2 px: 0.12 px with 5 % beyond 0.5 px).
  double min_relative_sharpness = 0.4;
  void validate() const;  // throws Error naming the field
};

// Reference sharpness of a sequence: the median of the upper half of the sharpness of the views
// where the board was found (and not already rejected). 0 when there is none.
double sharpnessReference(const std::vector<ViewObservations>& views);

// Marks the soft views rejected (rejected = true, rejected_reason says by how much) and returns
// how many it marked. Views without a board or already rejected are left alone. Needs
// focus.sharpness (detectBoard fills it by default, or call measureFocus).
int rejectSoftViews(std::vector<ViewObservations>& views, const FocusOptions& options = {});

}  // namespace previz::calib
