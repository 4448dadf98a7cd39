#pragma once
// Depth beyond the visual hull: photo-consistency along each main-camera ray inside the hull.
// The hull is a superset of the actor; where every silhouette contains a concavity (the crease
// between backpack and torso, the gap between arm and torso) its depth lies in front of the
// true surface. For each pixel inside the depth camera's silhouette, candidate depths from the
// hull entry backwards (inside the hull only) are scored by the colour agreement of the depth
// camera's plate with the witness plates at the candidate's projections (linear light, each
// plate divided by its camera's gain), the witnesses that cannot see the candidate (it lies far
// behind their own hull surface) left out, and a witness that must see it (it lies on that
// witness' hull surface) vetoing it when it disagrees. The hull depth stays where it is
// photo-consistent or where nothing deeper is decisively better; the nearest consistent
// candidate wins (the best-scoring one pushes pixels behind the surface: measured).
// Conventions: docs/conventions.md.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carving/hull.h"
#include "core/rig.h"

namespace previz::carving {

struct RefineOptions {
  double search_m = 0.25;   // how far behind the hull entry candidates go (along z)
  double step_m = 0.005;    // candidate spacing (along z)
  // Colour distance (relative, see refine.cpp) under which a witness agrees with the plate.
  double agree = 0.10;
  // The best 'best_of' visible witnesses are averaged into a candidate's cost (occlusion by
  // other body parts makes the rest disagree); a candidate needs that many visible witnesses.
  int best_of = 2;
  // A witness sees a candidate when it lies at most this far behind the witness' own hull
  // surface at its projection (the hull's concavities hide the true surface by up to this).
  double visibility_m = 0.22;
  // A witness that has the candidate on its own hull surface (at most veto_m behind it) would
  // see it if it were matter (the hull holds all of it); its colour distance above 'veto' rules
  // the candidate out. This is what carves the air of a same-coloured crease that the best
  // two witnesses agree on.
  double veto = 0.3;
  double veto_m = 0.05;
  // A deeper candidate replaces the hull entry only when its cost is below 'agree' and below
  // the entry's cost times 'margin'.
  double margin = 0.5;
  int threads = 0;
  void validate() const;  // throws Error naming the field
};

// One camera's plate for refinement: 8-bit BGR (sRGB-encoded), the camera's full image size,
// and its linear gain (the plate's linear radiance = gain x the scene's); empty = not used.
// gain <= 0 = unknown: a witness' gain is then estimated from the frame relative to the depth
// camera's (refine.cpp, estimateGains); the depth camera's unknown gain is taken as 1 (only
// the ratios matter).
struct Plate {
  cv::Mat bgr;
  double gain = 1.0;
};

struct RefineStats {
  long long pixels = 0;      // pixels with a finite hull depth
  long long inconsistent = 0;  // whose hull entry is not photo-consistent
  long long moved = 0;       // given a deeper depth
  double ms = 0;
  std::vector<std::string> witnesses_used;
  std::vector<double> witness_gains;         // the gains used, same order
  std::vector<std::string> gains_estimated;  // witnesses whose gain was estimated
  std::vector<int> gain_samples;             // points each estimate is the median of
};

// Refined depth of 'camera' (CV_32FC1, z along its axis, +inf where hull_depth is): hull_depth
// is Carver::depth(hull, camera, silhouette) (the refined depth is never nearer than it).
// witness_plates and witness_masks follow the carver's camera order (masks: the silhouettes
// carve() was given; a camera with an empty plate or mask is not used). Throws Error naming the
// camera when a plate or mask has the wrong size or type.
cv::Mat refineDepth(const Carver& carver, const VisualHull& hull, const RigCamera& camera,
                    const Plate& plate, const cv::Mat& hull_depth,
                    const std::vector<Plate>& witness_plates,
                    const std::vector<cv::Mat>& witness_masks, const RefineOptions& options = {},
                    RefineStats* stats = nullptr);

// Photo hull with iterated visibility (photoHullDepth). Kutulakos & Seitz 2000 carve what no
// camera sees consistently, visibility re-derived from what is left; here the "scene" is one
// refined depth map per camera. The depth camera is refined as by refineDepth; then every
// witness's depth is refined the same way (the other witnesses and the depth camera as
// references), and those depths decide free space for the depth camera's second pass: a point
// that free_views witnesses see through (their refined surface lies more than free_m behind it
// at its projection) is air, both at the hull entry and for deeper candidates; where the entry
// is air and nothing deeper is photo-consistent, the depth goes to the first point along the ray
// that no witness sees through. A witness that sees a point by its refined depth and disagrees
// in colour rules it out (seen_veto). This carves some of the crease air that stays
// photo-consistent because the parts on either side share a colour, but only where a witness's
// own refinement found the deeper surface. Measured on the synthetic studio
// (tests/carving/refine_test.cpp), against refineDepth: +0.03 to +1.0 point at 10 cm in front,
// +1 to +6 at 5 cm; behind within 0.13 point at 10 cm, 0.4 at 5 cm. The witnesses' refined
// depths are what limits it: their own creases keep their air (with the true witness depths it
// would reach 99.4 % at t = 7 s instead of 95.6 %). Refined visibility (hidden_m: a point that
// far behind a witness's refined surface is hidden from it) pushes depth behind the surface
// (measured 10 cm behind at t = 7 s: 99.76 % -> 98.67 % with 5 cm), so it is off by default;
// more rounds changed nothing (2 rounds: +0.05 point for twice the witness time).
// About 1 s per frame on 2 cores at 8 x 1280x720 witnesses (5x refineDepth).
struct PhotoHullOptions {
  RefineOptions refine;  // every view's refinement (the depth camera's and the witnesses')
  // Rounds of (witnesses refined, then the depth camera with their free space) after the depth
  // camera's first pass; each round's witnesses see the depth camera's last depth. 0 = the
  // result of refineDepth (with edge_jump_m > 0, followed by the occlusion-edge step).
  int rounds = 1;
  // A witness sees through a point its refined depth (the nearest over the 3x3 pixels around
  // the point's projection) lies this far behind. 3 -> 1 cm measured: +0.02 to +0.17 point at
  // 10 cm in front on the six test frames, behind within 0.02 point; on 4 witnesses at 320x180
  // (a witness pixel 2 cm wide) +0.1 to +0.8 point at 5 cm in front, behind within 0.1 point.
  double free_m = 0.01;
  int free_views = 1;     // ... and this many such witnesses make the point air (2: no gain)
  double hidden_m = 0;    // > 0: a point this far behind a witness's refined depth is hidden
  // The witnesses' depth is refined at every witness_stride-th pixel in each direction and
  // spread over the block (free space needs it to a few cm; 1 = every pixel). Measured on the
  // bench frame (bench_carving, one thread): 984 -> 605 ms CPU a call (witnesses 785 -> 373 ms);
  // on the six test frames the ordering figures move by at most +0.3 / -0.02 point.
  int witness_stride = 2;
  // Where a pixel's hull entry and its whole search range (refine.search_m) are air, its depth
  // goes to the first point along the ray, up to this far behind the entry, that no witness sees
  // through (before: it kept the hull depth). Measured on the synthetic studio (refine_test.cpp):
  // t = 1 s 98.76 -> 98.98 % at 10 cm in front, "behind" unchanged.
  double air_search_m = 1.0;
  // A witness sees a point when the point lies at most seen_m behind the witness's refined
  // depth; its colour distance above seen_veto then rules the point out (0 = off), as the hull's
  // veto (refine.veto, veto_m) does for points on the witness's hull surface, but from the
  // refined surface and with a tighter threshold. Measured on the six test frames
  // (refine_test.cpp): +0.1 to +0.34 point at 10 cm in front (t = 2.5 s 99.19 -> 99.53 %), +0.6
  // to +3.1 at 5 cm; behind -0.11 to +0.04 at 10 cm, -0.1 to -0.4 at 5 cm (a witness's depth
  // that is itself too deep claims to see a point that is hidden from it).
  double seen_veto = 0.15, seen_m = 0.02;
  // Occlusion edges of the depth camera's result, settled by the plate's blend: where a pixel
  // lies between a neighbour more than edge_jump_m deeper and, opposite, one at its own depth
  // (within edge_jump_m / 2; horizontal, vertical or diagonal), and those two neighbours differ
  // in colour by at least edge_contrast (refine.cpp's colour distance), the pixel's colour is
  // read as a blend of theirs: with less than edge_alpha of the near colour in it, the deeper
  // surface covers its centre, and its depth goes to the deeper neighbour's (the nearest point
  // inside the hull within 3 cm of it). The hull widens every occluder, so a near pixel at an
  // edge is often the air beside it; in the same colour nothing can be read (left as it is).
  // edge_jump_m 0 = off. Measured on the six test frames (refine_test.cpp), 10 cm in front:
  // +0.1 to +0.4 point (t = 1 s 99.30 -> 99.52 %, t = 8.5 s 99.41 -> 99.59 %), behind -0.05 to
  // +0.03; on 4 witnesses and a 320x180 main camera (an arm 3 px wide) +0.3 to +1.4 point in
  // front but -0.4 to -1.0 behind.
  double edge_jump_m = 0.05, edge_alpha = 0.3, edge_contrast = 0.3;
  void validate() const;  // throws Error naming the field (the refine fields as refineDepth's)
};

struct PhotoHullStats {
  RefineStats depth;        // the depth camera's last pass (gains, witnesses used)
  long long free_space = 0;  // depth-camera pixels whose hull entry is air (free space)
  std::vector<long long> witness_pixels, witness_moved;  // per witness used, last round
  long long edge_moved = 0;  // depth-camera pixels moved to the deeper side of an edge
  double witness_ms = 0;     // refining the witnesses (all rounds)
  double ms = 0;             // the whole call
};

// The depth camera's depth beyond the hull by the photo hull above: same inputs, conventions and
// errors as refineDepth (never nearer than hull_depth, +inf exactly where it is).
cv::Mat photoHullDepth(const Carver& carver, const VisualHull& hull, const RigCamera& camera,
                       const Plate& plate, const cv::Mat& hull_depth,
                       const std::vector<Plate>& witness_plates,
                       const std::vector<cv::Mat>& witness_masks,
                       const PhotoHullOptions& options = {}, PhotoHullStats* stats = nullptr);

}  // namespace previz::carving
