#pragma once
// The corners of a dark square marker (a printed tag or quadtree marker, light surround) from
// its edges, on a linear-light image. refineCornerByEdges (calib's quadtree markers, whose edges
// are short and have neighbours): one corner from its two half-edges; each edge's position is
// measured across it (the centroid of the dark -> light intensity step, along the image normal)
// at points from 3 px to min(0.45 edge, 16 px) away from the corner, a line is fitted through
// them, and the corner is where the two lines meet.
// Why not cornerSubPix: an L-shaped corner is not point-symmetric, and under blur its rounded tip
// pulls cornerSubPix's gradient condition into the black (on the studio's quadtree views, 1 px
// blur: 0.3 px median, diagonally into the marker); a straight edge's step, away from the tip, is
// symmetric, so its centroid lies on the edge, and on linear light (not sRGB codes) the step's
// profile is the blur's own. The samples stay 3 px from the tip (the other edge's blur) and
// within 16 px (the lens bends edges: over 16 px at k1 = -0.22 the sagitta is ~0.01 px).
// fitEdgeLine (tracking's tags, clear from corner to corner): one whole edge at a time, its
// corners then where adjacent lines meet (intersectLines).
#include <array>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace previz {

struct MarkerCorner {
  Eigen::Matrix3d H;                      // marker plane -> pixels (from the marker's corners)
  Eigen::Vector2d corner;                 // the corner, marker plane
  std::array<Eigen::Vector2d, 2> along;   // unit vectors (marker plane) of its two edges, into the marker
  double px_per_unit = 0;                 // image pixels per marker-plane unit near the corner
  double edge_px = 0;                     // the marker's shortest edge in the image
  double profile_half_px = 0;             // clear distance either side of the edge (border bit, gap)
};

// Bilinear sample of a CV_32FC1 image at pixel (x, y) (OpenCV's convention: (0, 0) is the centre of
// the top-left pixel); NaN where the 2 x 2 neighbourhood leaves the image.
float bilinearAt(const cv::Mat& image, double x, double y);

// lin: CV_32FC1, linear light. False (out untouched) when an edge has too few measurable points
// (too short, too faint, leaves the image) or the two edges are near parallel.
bool refineCornerByEdges(const cv::Mat& lin, const MarkerCorner& c, Eigen::Vector2d& out);

// A whole straight edge at once (a tag's side, clear from corner to corner): the line a x + b y = c
// ((a, b) unit) of the dark -> light step between image points a and b, measured once a pixel
// from margin_px after a to margin_px before b, across the segment towards light_side (any
// vector pointing to the light side), the profile read reach_px either side of the step. False
// when the segment is too short or fewer than half of its points could be measured.
bool fitEdgeLine(const cv::Mat& lin, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                 const Eigen::Vector2d& light_side, double reach_px, double margin_px,
                 Eigen::Vector3d& line);

// The points fitEdgeLine fits (one a pixel, on the step's centroid); false when the segment is
// too short or fewer than half of its points could be measured (points then holds those that were).
bool measureEdgePoints(const cv::Mat& lin, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                       const Eigen::Vector2d& light_side, double reach_px, double margin_px,
                       std::vector<Eigen::Vector2d>& points);

// Where two such lines meet; false when they are near parallel (|sin| of the angle < 0.2).
bool intersectLines(const Eigen::Vector3d& l0, const Eigen::Vector3d& l1, Eigen::Vector2d& out);

}  // namespace previz
