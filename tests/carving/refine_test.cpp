// Depth beyond the visual hull (carving/refine.h), item 2 of issue 5: a virtual plane 5, 10 and
// 20 cm in front of / behind the true actor surface, per main pixel: is the actor put on the
// right side of it? Silhouettes are the true actor mesh rasterized through each camera's true
// lens (hull_fixture.h); the plates are rendered by the synthetic studio (stage + actor, 4 spp,
// sensor noise 2 grey levels, a different gain per camera); witnesses at 1280x720, the main
// camera at 960x540. Truth: the rasterized depth of the actor mesh in the main camera.
//
// What the photo hull still misses at 10 cm in front (measured once with the true witness depths
// from rasterize(), a diagnosis only; nothing below uses them). (a) colour-consistent air: two
// or more witnesses that truly see the final depth's point (nothing of the actor in front of it)
// agree with the plate in colour; (b) the true surface point is seen by no witness (none has it
// within 2 cm of its own true depth); (c) neither (the point is accepted through the loose
// hull-based visibility: witnesses that in truth are occluded there):
//            misses   (a)   (b)   (a and b)   (c)   moved off the hull   components (largest)
//   t = 7 s    487    323     6       1       159          128           27 (281, 90, 28, 27)
//   t = 2.5 s   45     17     0       0        28            9           17 (15, 4, 3, 3)
// So the true surface is nearly always seen by some witness; the crease air survives because
// same-coloured parts either side make it photo-consistent. The misses are compact at t = 7 s
// (426 of 487 in components >= 20 px) and scattered at t = 2.5 s. A plane fitted to the true
// depths of the correct pixels around each component on its far side (deeper than the
// component's median) predicts 413 of the 487 true depths within 5 cm (the whole ring: 250), so
// the hidden surface does continue from its seen neighbours; but the same-coloured near side is
// confirmed as well. A prior that moved only unconfirmed pixels (the median depth of confirmed
// neighbours of similar plate colour within 5, 8 or 15 px, colour 0.1 or 0.2, or only deeper
// neighbours) was tried and not kept: at 8 px it gained at most 0.09 point at 10 cm in front
// (t = 7 s 95.33 -> 95.42 % with witness_stride 1, nothing at t = 1, 2.5, 5.5 s); 15 px and deeper-only pushed 0.02 to
// 0.3 point behind.
//
// Where the photo hull's misses at 10 cm in front lie now (measured once, a diagnosis): on the
// five test frames other than t = 7 s (0 to 55 misses each) 78-100 % of them are within 1 px and
// all within 2 px of a jump of more than 5 cm in the true depth, mostly left at the hull depth:
// the hull's widened occluders beside a part of the same colour. At t = 7 s 129 of 431 are; the
// rest is the pocket (connected misses of 269 and 82 px). Not kept: the occlusion-edge step on
// the witnesses' refined depths too (+0.02 point at most); each witness refined against the
// witnesses refined before it in the same round (+0.04 / +0.06 point at t = 2.5 / 7 s, nothing
// elsewhere). Nor is the studio's lighting the missing cue: with the actor shadowed by its own
// parts from the key light (as the floor is), the photo hull did worse at 10 cm in front (t = 1 s
// 99.52 -> 98.82 %, t = 2.5 s 99.60 -> 98.90 %, t = 7 s 95.87 -> 95.52 %), so the studio renders
// as before.
// Nor windows instead of pixels (measured once at t = 6.5 s with the witnesses that truly see
// the point, true depths, a diagnosis only): over 5x5 main pixels on a plane at the candidate
// depth, the zero-mean normalized cross-correlation of brightness ranks the true depth above
// ours on 124 of 233 misses, as it ranks it above a point 10 cm in front on 124 of 186 correct
// pixels: chance, the plates' smooth shading holds nothing to match; the windowed colour
// distance on 159 of 233, means 0.186 against 0.194, within the noise. Nor a textured costume:
// the actor's albedo times 1 + 0.3 (or 0.5) x value noise at 3 and 1.2 cm on each part's
// surface took t = 7 s from 95.87 to 96.75 (97.45) % in front and t = 6.5 s from 97.67 to 97.68
// (98.13) %, with "behind" down to 98.97 %: of the several witnesses that see the air, the two
// that agree best still find a match. Sixteen witnesses: PhotoHullWithSixteenWitnesses.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

#include "carving/keyer.h"
#include "carving/refine.h"
#include "core/error.h"
#include "datasets/render.h"
#include "hull_fixture.h"

namespace previz::carving {
namespace {

using namespace previz::carving::test;

constexpr int kMainW = 960, kMainH = 540;

struct PlateFrame {
  StudioFrame studio;
  std::vector<Plate> witness_plates;
  Plate main_plate;
};

// Gains as a studio sets them (+-10 %), different for every camera.
double gainOf(int camera) { return 1.0 + 0.1 * std::sin(3.0 * camera + 1.0); }

PlateFrame makePlateFrame(double time_s, int witness_cameras = 8) {
  PlateFrame f{makeStudioFrame(time_s, kMainW, kMainH, false, nullptr, witness_cameras), {}, {}};
  const synth::Studio studio(synth::StudioConfig{});
  const synth::Scene scene = studio.sceneAt(time_s, synth::kLayerStage | synth::kLayerActor);
  auto render = [&](const RigCamera& c, int index) {
    synth::RenderOptions o;
    o.samples_per_pixel = 4;
    o.gain = gainOf(index);
    o.noise_sigma = 2.0;
    o.camera_index = index;
    o.truth = false;
    return Plate{synth::renderView(c.camera, c.T_world_cam, scene, o).bgr, o.gain};
  };
  for (size_t c = 0; c < f.studio.witnesses.size(); ++c)
    f.witness_plates.push_back(render(f.studio.witnesses[c], static_cast<int>(c)));
  f.main_plate = render(f.studio.main, static_cast<int>(f.studio.witnesses.size()));
  return f;
}

struct Ordering {
  double front[3], behind[3];  // at 5, 10, 20 cm
};
constexpr double kPlanes[3] = {0.05, 0.10, 0.20};
// How much "behind" the photo hull may give up against refineDepth at 5, 10 and 20 cm: its veto
// from the witnesses' refined depths (PhotoHullOptions::seen_veto) wrongly rules out some true
// surface points where a witness's own depth is too deep, and a few near pixels at occlusion
// edges are read as the deeper side (edge_jump_m). Measured at most 0.52, 0.16 and 0.06 point on
// the six frames, for +0.1 to +6 points in front at 5 cm.
constexpr double kBehindSlack[3] = {0.006, 0.002, 0.001};

Ordering ordering(const cv::Mat& depth, const cv::Mat& truth) {
  Ordering o;
  for (int i = 0; i < 3; ++i) {
    o.front[i] = orderedFraction(depth, truth, kPlanes[i], true);
    o.behind[i] = orderedFraction(depth, truth, kPlanes[i], false);
  }
  return o;
}

struct Result {
  Ordering hull, refined, photo;  // photo: photoHullDepth (only with photo_hull)
  RefineStats stats;
  PhotoHullStats photo_stats;
};

// Never nearer than the hull (the actor lies inside it), and finite exactly where it is.
void expectBeyondHull(const cv::Mat& hull_depth, const cv::Mat& depth, const char* what) {
  int nearer = 0, finite_mismatch = 0;
  for (int v = 0; v < hull_depth.rows; ++v)
    for (int u = 0; u < hull_depth.cols; ++u) {
      const float h = hull_depth.at<float>(v, u), d = depth.at<float>(v, u);
      finite_mismatch += std::isfinite(h) != std::isfinite(d);
      nearer += std::isfinite(h) && d < h;
    }
  EXPECT_EQ(nearer, 0) << what;
  EXPECT_EQ(finite_mismatch, 0) << what;
}

// The frame carved at 5 mm from the true masks, and the main camera's hull depth.
struct CarvedFrame {
  static HullOptions fine() {
    HullOptions o;
    o.voxel_m = 0.005;
    return o;
  }
  static Silhouettes masks(const PlateFrame& f) {
    Silhouettes s;
    s.masks = f.studio.masks;
    return s;
  }
  explicit CarvedFrame(const PlateFrame& f)
      : carver(f.studio.witnesses, fine()),
        hull(carver.carve(masks(f))),
        hull_depth(carver.depth(hull, f.studio.main, f.studio.main_raster.mask)) {}
  // photoHullDepth of f's main camera from this hull (f: the frame it was carved from).
  cv::Mat photoHull(const PlateFrame& f, const PhotoHullOptions& options = {},
                    PhotoHullStats* stats = nullptr) const {
    return photoHullDepth(carver, hull, f.studio.main, f.main_plate, hull_depth, f.witness_plates,
                          f.studio.masks, options, stats);
  }
  Carver carver;
  VisualHull hull;
  cv::Mat hull_depth;
};

// Carves the frame, takes the hull depth and refines it (and with photo_hull also by the photo
// hull); prints item 2 for each.
Result run(const PlateFrame& f, const char* label, bool photo_hull = false) {
  const CarvedFrame c(f);
  const Carver& carver = c.carver;
  const VisualHull& hull = c.hull;
  const cv::Mat& hull_depth = c.hull_depth;
  Result r;
  const cv::Mat refined = refineDepth(carver, hull, f.studio.main, f.main_plate, hull_depth,
                                      f.witness_plates, f.studio.masks, RefineOptions{}, &r.stats);
  const cv::Mat& truth = f.studio.main_raster.depth;
  r.hull = ordering(hull_depth, truth);
  r.refined = ordering(refined, truth);
  std::printf("%s: %lld pixels, %lld not photo-consistent at the hull, %lld moved deeper, %.0f ms\n",
              label, r.stats.pixels, r.stats.inconsistent, r.stats.moved, r.stats.ms);
  cv::Mat photo;
  if (photo_hull) {
    photo = c.photoHull(f, {}, &r.photo_stats);
    r.photo = ordering(photo, truth);
    std::printf("  photo hull: %lld pixels with free space at the hull entry, %lld moved deeper, "
                "%lld moved across an occlusion edge, %.0f ms per frame (CPU, %.0f ms of it "
                "refining the witnesses)\n",
                r.photo_stats.free_space, r.photo_stats.depth.moved, r.photo_stats.edge_moved,
                r.photo_stats.ms, r.photo_stats.witness_ms);
  }
  for (int i = 0; i < 3; ++i) {
    std::printf("  plane %2.0f cm in front: hull %.3f %%, refined %.3f %%", 100 * kPlanes[i],
                100 * r.hull.front[i], 100 * r.refined.front[i]);
    if (photo_hull) std::printf(", photo hull %.3f %%", 100 * r.photo.front[i]);
    std::printf(" | behind: hull %.3f %%, refined %.3f %%", 100 * r.hull.behind[i],
                100 * r.refined.behind[i]);
    if (photo_hull) std::printf(", photo hull %.3f %%", 100 * r.photo.behind[i]);
    std::printf("\n");
  }
  expectBeyondHull(hull_depth, refined, "refineDepth");
  EXPECT_EQ(r.stats.witnesses_used.size(), f.studio.witnesses.size());
  if (photo_hull) {
    expectBeyondHull(hull_depth, photo, "photoHullDepth");
    EXPECT_EQ(r.photo_stats.depth.witnesses_used.size(), f.studio.witnesses.size());
    EXPECT_EQ(r.photo_stats.witness_moved.size(), f.studio.witnesses.size());
  }
  return r;
}

// t = 4 s, the frame of item 1 (walking along the back of the stage, seen from the side): the
// hull puts 1.6 % of the actor pixels more than 10 cm in front (the creases between arms and
// torso and at the hips, that every silhouette contains). Photo-consistency takes the goal:
// measured 99.68 % in front, 99.83 % behind at 10 cm; the photo hull 99.78 % / 99.88 % (5 cm in
// front: 96.40 % -> 98.04 %).
TEST(RefineDepth, OrdersActorWithinTenCentimetresBeyondTheHull) {
  const PlateFrame f = makePlateFrame(4.0);
  const Result r = run(f, "t = 4 s", true);
  EXPECT_GE(r.photo.front[1], 0.995);
  EXPECT_GE(r.photo.behind[1], 0.995);
  EXPECT_GT(r.photo_stats.edge_moved, 0);
  EXPECT_GE(r.photo.front[2], 0.999);
  EXPECT_GE(r.photo.behind[2], 0.999);
  EXPECT_GE(r.photo.front[0], r.refined.front[0] + 0.005);
  EXPECT_GE(r.photo.behind[0], r.refined.behind[0] - kBehindSlack[0]);
  EXPECT_LT(r.hull.front[1], 0.99);  // the hull alone misses the goal here (so this can fail)
  EXPECT_GE(r.refined.front[1], 0.995);
  EXPECT_GE(r.refined.behind[1], 0.995);
  EXPECT_GE(r.refined.front[2], 0.999);
  EXPECT_GE(r.refined.behind[2], 0.999);
  EXPECT_GT(r.refined.front[0], r.hull.front[0] + 0.03);
  EXPECT_GE(r.refined.behind[0], 0.99);

  // The gains matter: the same plates compared without them (every gain taken as 1) ...
  PlateFrame no_gain = f;
  for (Plate& p : no_gain.witness_plates) p.gain = 1.0;
  no_gain.main_plate.gain = 1.0;
  const Result n = run(no_gain, "t = 4 s, gains ignored");
  EXPECT_LT(n.refined.front[1] + n.refined.behind[1], r.refined.front[1] + r.refined.behind[1]);
  // ... and the witnesses' gains unknown: estimated from the frame against the main camera's.
  PlateFrame unknown = f;
  for (Plate& p : unknown.witness_plates) p.gain = 0.0;
  const Result e = run(unknown, "t = 4 s, witness gains estimated");
  ASSERT_EQ(e.stats.gains_estimated.size(), f.witness_plates.size());
  int measured = 0;
  for (size_t c = 0; c < f.witness_plates.size(); ++c) {
    std::printf("  %s: gain %.4f estimated from %d points (true %.4f)\n",
                e.stats.gains_estimated[c].c_str(), e.stats.witness_gains[c],
                e.stats.gain_samples[c], f.witness_plates[c].gain);
    if (e.stats.gain_samples[c] < 200) continue;  // facing the actor's back: hardly used
    ++measured;
    EXPECT_NEAR(e.stats.witness_gains[c], f.witness_plates[c].gain, 0.01) << c;
  }
  EXPECT_GE(measured, 4);
  // Measured 99.61 % in front / 99.87 % behind (given gains: 99.68 % / 99.83 %).
  EXPECT_GE(e.refined.front[1], 0.995);
  EXPECT_GE(e.refined.behind[1], 0.995);
}

// The hardest of nine frames for the hull: t = 7 s (turning, an upper arm against the torso
// beside the backpack, 8.5 % of the pixels more than 10 cm in front) and t = 2.5 s (7.0 %). The
// red sleeve in front of the red shirt and the dark legs side by side are the same colour in
// every witness, so much of the air in their creases is photo-consistent too and stays.
// Measured at 10 cm in front, hull -> refineDepth -> photoHullDepth: t = 7 s 91.46 % -> 95.25 %
// -> 95.87 %, t = 2.5 s 93.03 % -> 98.83 % -> 99.60 % (5 cm: 90.88 -> 92.50 %, 91.45 -> 97.87 %);
// behind at 10 cm 99.76 / 99.73 % at t = 7 s, 99.78 / 99.62 % at t = 2.5 s. The photo hull
// carves only the air some witness's own refinement looks through. With the witnesses' TRUE
// depths in place of their refined ones (a diagnosis, measured once and not kept: free space
// from the exact pixel's depth, free_m 8 mm, with the air search) it reaches 99.44 % at t = 7 s
// and 99.72-99.93 % at t = 1, 2.5, 4, 8.5 s: the crease air is seen through by some witness, but
// each witness's own depth holds its creases' air as the depth camera's does (at t = 7 s the
// refined witness depths lie more than 5 cm in front on 4-12 % of their pixels, the hull's on
// 9-20 %), and further rounds do not change them. Asserted as regression bounds, with behind
// kept >= 99.5 %.
TEST(RefineDepth, ImprovesTheHardestFramesWithoutPushingBehind) {
  struct Case {
    double time_s, front_10cm, photo_front_10cm;
  };
  for (const Case c : {Case{7.0, 0.95, 0.958}, Case{2.5, 0.985, 0.995}}) {
    const PlateFrame f = makePlateFrame(c.time_s);
    const std::string label = "t = " + std::to_string(c.time_s).substr(0, 3) + " s";
    const Result r = run(f, label.c_str(), true);
    EXPECT_GE(r.refined.front[1], c.front_10cm) << label;
    EXPECT_GE(r.refined.front[1], r.hull.front[1] + 0.035) << label;
    EXPECT_GE(r.refined.behind[1], 0.995) << label;
    EXPECT_GE(r.refined.front[2], r.hull.front[2]) << label;
    EXPECT_GE(r.refined.behind[2], 0.998) << label;
    EXPECT_GE(r.photo.front[1], c.photo_front_10cm) << label;
    EXPECT_GE(r.photo.front[0], r.refined.front[0]) << label;
    EXPECT_GE(r.photo.front[2], r.refined.front[2]) << label;
    for (int i = 0; i < 3; ++i)
      EXPECT_GE(r.photo.behind[i], r.refined.behind[i] - kBehindSlack[i]) << label << " " << i;
    EXPECT_GE(r.photo.behind[1], 0.995) << label;
  }
}

// Other frames, so that the photo hull is not tuned to the three above. Measured at 10 cm in
// front (hull / refineDepth / photoHullDepth): t = 1 s 95.05 / 98.30 / 99.52 %, t = 5.5 s
// 100 / 100 / 100 %, t = 8.5 s 95.61 / 98.92 / 99.59 %; 10 cm behind (refineDepth / photo hull)
// 99.83 / 99.78 %, 99.60 / 99.52 %, 99.77 / 99.81 %; 5 cm behind 99.56 / 99.43 %, 99.33 /
// 99.04 %, 99.27 / 99.03 %. Item 2's 99.5 % at 10 cm is asserted on both sides.
TEST(RefineDepth, PhotoHullImprovesOtherFramesWithoutPushingBehind) {
  struct Case {
    double time_s, photo_front_10cm;
  };
  for (const Case c : {Case{1.0, 0.995}, Case{5.5, 0.999}, Case{8.5, 0.995}}) {
    const PlateFrame f = makePlateFrame(c.time_s);
    const std::string label = "t = " + std::to_string(c.time_s).substr(0, 3) + " s";
    const Result r = run(f, label.c_str(), true);
    EXPECT_GE(r.photo.front[1], c.photo_front_10cm) << label;
    for (int i = 0; i < 3; ++i) {
      EXPECT_GE(r.photo.front[i], r.refined.front[i]) << label << " " << i;
      EXPECT_GE(r.photo.behind[i], r.refined.behind[i] - kBehindSlack[i]) << label << " " << i;
    }
    EXPECT_GE(r.photo.behind[1], 0.995) << label;
  }
}

// The occlusion-edge step alone (PhotoHullOptions::edge_jump_m), at t = 8.5 s, where most of the
// photo hull's misses at 10 cm in front lie on a 1 px band beside the forearm and the hand (the
// hull widens them; the plate there blends skin with the trousers behind). Measured: 56 pixels
// moved, 10 cm in front 99.41 -> 99.59 %, behind 99.82 -> 99.81 %.
TEST(RefineDepth, OcclusionEdgesGiveTheBlendedPixelsToTheDeeperSurface) {
  const PlateFrame f = makePlateFrame(8.5);
  const CarvedFrame c(f);
  PhotoHullOptions off;
  off.edge_jump_m = 0;
  PhotoHullStats with_stats, without_stats;
  const cv::Mat with = c.photoHull(f, {}, &with_stats);
  const cv::Mat without = c.photoHull(f, off, &without_stats);
  const cv::Mat& truth = f.studio.main_raster.depth;
  const Ordering w = ordering(with, truth), n = ordering(without, truth);
  std::printf("  edges: %lld pixels moved; 10 cm in front %.3f -> %.3f %%, behind %.3f -> %.3f %%\n",
              with_stats.edge_moved, 100 * n.front[1], 100 * w.front[1], 100 * n.behind[1],
              100 * w.behind[1]);
  EXPECT_EQ(without_stats.edge_moved, 0);
  EXPECT_GT(with_stats.edge_moved, 20);
  int changed = 0, nearer = 0;
  for (int v = 0; v < with.rows; ++v)
    for (int u = 0; u < with.cols; ++u) {
      const float a = with.at<float>(v, u), b = without.at<float>(v, u);
      if (!std::isfinite(b)) continue;
      changed += a != b;
      nearer += a < b;
    }
  EXPECT_EQ(changed, with_stats.edge_moved);  // only the edge pixels differ ...
  EXPECT_EQ(nearer, 0);                       // ... and only deeper
  EXPECT_GE(w.front[1], n.front[1] + 0.001);
  EXPECT_GE(w.behind[1], n.behind[1] - 0.0005);
}

// Thirteen frames that none of the settings above was chosen on, every half second of the take
// not used above. Measured at 10 cm (hull | photo hull in front / photo hull behind):
//   0.5 s 95.13 | 99.56 / 99.69    1.5 s 98.37 | 99.61 / 99.70    2.0 s 95.04 | 99.75 / 99.68
//   3.0 s 97.27 | 99.14 / 99.79    3.5 s 99.52 | 100   / 99.93    4.5 s 98.90 | 99.38 / 99.62
//   5.0 s 99.73 | 99.91 / 99.78    6.0 s 99.67 | 99.97 / 99.64    6.5 s 90.66 | 97.67 / 99.63
//   7.5 s 95.19 | 99.01 / 99.85    8.0 s 96.26 | 99.23 / 99.63    9.0 s 95.92 | 99.46 / 99.68
//   9.5 s 99.59 | 99.95 / 99.79
// Item 2 (>= 99.5 % on both sides) holds on 7 of them (before the air search, seen_veto, 1 cm
// free space and the edge step: on 5, with the same "behind" 0.0-0.2 point higher).
TEST(RefineDepth, PhotoHullOnFramesItWasNotTunedOn) {
  int met = 0;
  for (const double t : {0.5, 1.5, 2.0, 3.0, 3.5, 4.5, 5.0, 6.0, 6.5, 7.5, 8.0, 9.0, 9.5}) {
    const PlateFrame f = makePlateFrame(t);
    const CarvedFrame c(f);
    const cv::Mat& hull_depth = c.hull_depth;
    const cv::Mat photo = c.photoHull(f);
    const cv::Mat& truth = f.studio.main_raster.depth;
    const double hull_front = orderedFraction(hull_depth, truth, 0.10, true);
    const double front = orderedFraction(photo, truth, 0.10, true);
    const double behind = orderedFraction(photo, truth, 0.10, false);
    std::printf("  t = %.1f s, 10 cm: hull %.2f %% | photo hull in front %.2f %%, behind %.2f %%\n", t,
                100 * hull_front, 100 * front, 100 * behind);
    EXPECT_GE(front, hull_front) << t;
    EXPECT_GE(front, 0.975) << t;
    EXPECT_GE(behind, 0.995) << t;
    met += front >= 0.995 && behind >= 0.995;
  }
  EXPECT_GE(met, 7);
}

// Fewer witnesses (issue 5 allows 4 to 16): the frame's plates and masks for the witnesses
// i * 8 / n of the studio's eight (n = 6: all but two; n = 4: every other one), the same main
// camera. The photo hull needs two witnesses that agree and one that sees through the air, so
// with fewer of them it carves less and pushes more depth behind; measured at 10 cm
// (hull -> photo hull in front / photo hull behind; the hull is >= 99.94 % behind on all):
//   6 witnesses: t = 1 s 88.56 -> 98.76 / 98.95 %, t = 4 s 97.40 -> 99.47 / 99.55 %,
//                t = 7 s 87.62 -> 95.00 / 99.75 %
//   4 witnesses: t = 1 s 79.19 -> 97.06 / 98.91 %, t = 4 s 91.27 -> 98.84 / 99.25 %,
//                t = 7 s 87.23 -> 93.51 / 98.88 %
// (8 witnesses: tests above.) Item 2's 99.5 % is for the full rig; asserted here: still at
// least 2 points better in front than the hull, and >= 98.5 % behind.
TEST(RefineDepth, PhotoHullWithFewerWitnesses) {
  for (const double t : {1.0, 4.0, 7.0}) {
    const PlateFrame full = makePlateFrame(t);
    for (const int n : {6, 4}) {
      PlateFrame f = full;
      f.studio.witnesses.clear();
      f.studio.masks.clear();
      f.witness_plates.clear();
      for (int i = 0; i < n; ++i) {
        const size_t c = static_cast<size_t>(i * 8 / n);
        f.studio.witnesses.push_back(full.studio.witnesses[c]);
        f.studio.masks.push_back(full.studio.masks[c]);
        f.witness_plates.push_back(full.witness_plates[c]);
      }
      const CarvedFrame c(f);
      const cv::Mat photo = c.photoHull(f);
      const cv::Mat& truth = f.studio.main_raster.depth;
      const double hull_front = orderedFraction(c.hull_depth, truth, 0.10, true);
      const double hull_behind = orderedFraction(c.hull_depth, truth, 0.10, false);
      const double front = orderedFraction(photo, truth, 0.10, true);
      const double behind = orderedFraction(photo, truth, 0.10, false);
      std::printf("  %d witnesses, t = %.1f s, 10 cm: hull %.2f / %.2f %% | photo hull in front %.2f %%, "
                  "behind %.2f %%\n",
                  n, t, 100 * hull_front, 100 * hull_behind, 100 * front, 100 * behind);
      expectBeyondHull(c.hull_depth, photo, "photoHullDepth, fewer witnesses");
      EXPECT_GE(front, hull_front + 0.02) << n << " witnesses, t = " << t;
      EXPECT_GE(behind, 0.985) << n << " witnesses, t = " << t;
    }
  }
}

// The most witnesses issue 5 allows: 16, the studio rig's ring with twice the cameras (the
// azimuth step halved; heights and distances drawn as for 8), on the two frames where 8 fall
// furthest short in front (the torso strip between the near upper arm and the backpack, and the
// trousers between the legs). More silhouettes tighten the hull and give the photo hull more
// views to see through the air; measured at 10 cm (hull -> photo hull in front / photo hull
// behind), 8 -> 16 witnesses:
//   t = 6.5 s: 90.66 -> 97.67 / 99.63 %  ->  94.22 -> 98.21 / 99.30 %
//   t = 7 s:   91.46 -> 95.87 / 99.73 %  ->  94.00 -> 98.97 / 99.58 %
// Item 2 is still not met on either. "Behind" falls with 16: half of its misses (62 of 119 at
// t = 8 s, measured once) are actor pixels at the silhouette's rim where the main ray misses the
// hull (+inf depth; each added silhouette trims the rim by up to half a pixel; the compositor
// fills them from a neighbour, composite/compositor.h edge_fill_px), the rest pixels that free
// space from one more witness moved too deep. Also measured once (diagnostic, all 7 hardest
// frames 3, 4.5, 6.5, 7, 7.5, 8, 9 s; mean in front / behind, frames meeting item 2): 8 ring
// 0 of 7; 12 ring 99.13 / 99.61 %, 3 of 7; 16 ring 99.36 / 99.42 %, 1; 16 ring and 4 cameras
// 4.5-5 m up over the stage 99.68 / 99.35 %, 0 (t = 6.5 s in front 99.15 %). At a 1920x1080
// main camera: 16 ring 99.39 / 99.43 %, 2 of 7; 12 ring and 4 overhead 99.57 / 99.47 %, 1.
// Asserted: the hull at least 2 points tighter in front, the photo hull at least 0.5 point
// better in front and >= 99 % behind, never nearer than the hull.
TEST(RefineDepth, PhotoHullWithSixteenWitnesses) {
  for (const double t : {6.5, 7.0}) {
    Ordering hull[2], photo[2];
    for (const int i : {0, 1}) {
      const PlateFrame f = makePlateFrame(t, i == 0 ? 8 : 16);
      ASSERT_EQ(f.studio.witnesses.size(), i == 0 ? 8u : 16u);
      const CarvedFrame c(f);
      const cv::Mat depth = c.photoHull(f);
      expectBeyondHull(c.hull_depth, depth, "photoHullDepth, 16 witnesses");
      hull[i] = ordering(c.hull_depth, f.studio.main_raster.depth);
      photo[i] = ordering(depth, f.studio.main_raster.depth);
      std::printf("  %2zu witnesses, t = %.1f s, 10 cm: hull %.2f %% | photo hull in front %.2f %%, "
                  "behind %.2f %%\n",
                  f.studio.witnesses.size(), t, 100 * hull[i].front[1], 100 * photo[i].front[1],
                  100 * photo[i].behind[1]);
    }
    EXPECT_GE(hull[1].front[1], hull[0].front[1] + 0.02) << t;
    EXPECT_GE(photo[1].front[1], photo[0].front[1] + 0.005) << t;
    EXPECT_GE(photo[1].behind[1], 0.99) << t;
  }
}

TEST(RefineDepth, RejectsBadOptionsAndInputs) {
  RefineOptions o;
  o.step_m = 0;
  EXPECT_THROW(o.validate(), Error);
  o = RefineOptions{};
  o.margin = 1.5;
  EXPECT_THROW(o.validate(), Error);
  o = RefineOptions{};
  o.best_of = 0;
  EXPECT_THROW(o.validate(), Error);
  // Each photo-hull option out of its range, one at a time.
  const std::vector<std::pair<const char*, void (*)(PhotoHullOptions&)>> bad_photo = {
      {"free_views", [](PhotoHullOptions& p) { p.free_views = 0; }},
      {"refine.step_m", [](PhotoHullOptions& p) { p.refine.step_m = -1; }},
      {"free_m", [](PhotoHullOptions& p) { p.free_m = 0; }},
      {"witness_stride", [](PhotoHullOptions& p) { p.witness_stride = 0; }},
      {"air_search_m", [](PhotoHullOptions& p) { p.air_search_m = 0.5 * p.refine.search_m; }},
      {"seen_veto", [](PhotoHullOptions& p) { p.seen_veto = -0.1; }},
      {"seen_m", [](PhotoHullOptions& p) { p.seen_m = std::nan(""); }},
      {"edge_jump_m", [](PhotoHullOptions& p) { p.edge_jump_m = -0.05; }},
      {"edge_alpha", [](PhotoHullOptions& p) { p.edge_alpha = 0; }},
      {"edge_contrast", [](PhotoHullOptions& p) { p.edge_contrast = 0; }},
  };
  for (const auto& [field, spoil] : bad_photo) {
    PhotoHullOptions p;
    spoil(p);
    EXPECT_THROW(p.validate(), Error) << field;
  }

  const StudioFrame f = makeStudioFrame(4.0, 320, 180);
  Carver carver(f.witnesses, HullOptions{});
  Silhouettes s;
  s.masks = f.masks;
  const VisualHull hull = carver.carve(s);
  const cv::Mat depth = carver.depth(hull, f.main, f.main_raster.mask);
  std::vector<Plate> plates(f.witnesses.size());
  for (size_t c = 0; c < plates.size(); ++c)
    plates[c].bgr = cv::Mat(f.witnesses[c].camera.height, f.witnesses[c].camera.width, CV_8UC3,
                            cv::Scalar(0, 200, 0));
  const Plate wrong_size{cv::Mat(10, 10, CV_8UC3, cv::Scalar(0)), 1.0};
  try {
    refineDepth(carver, hull, f.main, wrong_size, depth, plates, f.masks);
    ADD_FAILURE() << "a plate of the wrong size was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, f.main.camera.name);
    EXPECT_NE(std::string(e.what()).find("plate"), std::string::npos) << e.what();
  }
  const Plate main{cv::Mat(180, 320, CV_8UC3, cv::Scalar(0, 0, 200)), 1.0};
  std::vector<Plate> too_few(plates.begin(), plates.end() - 1);
  EXPECT_THROW(refineDepth(carver, hull, f.main, main, depth, too_few, f.masks), Error);
  // A uniformly green world is photo-consistent nowhere with a red plate: nothing moves.
  RefineStats stats;
  const cv::Mat same = refineDepth(carver, hull, f.main, main, depth, plates, f.masks, {}, &stats);
  EXPECT_GT(stats.pixels, 100);
  EXPECT_EQ(stats.moved, 0);
  EXPECT_EQ(cv::countNonZero(same != depth), 0);
  EXPECT_THROW(photoHullDepth(carver, hull, f.main, wrong_size, depth, plates, f.masks), Error);
  EXPECT_THROW(photoHullDepth(carver, hull, f.main, main, depth, too_few, f.masks), Error);
  // No rounds: the photo hull is refineDepth, bit for bit.
  PhotoHullOptions no_rounds;
  no_rounds.rounds = 0;
  PhotoHullStats photo_stats;
  const cv::Mat photo =
      photoHullDepth(carver, hull, f.main, main, depth, plates, f.masks, no_rounds, &photo_stats);
  EXPECT_EQ(photo_stats.depth.moved, 0);
  EXPECT_EQ(cv::countNonZero(photo != same), 0);
  // (With rounds the green witnesses refine each other and carve free space the red plate
  // cannot contradict, so here the photo hull does move pixels; never nearer than the hull.)
  const cv::Mat carved = photoHullDepth(carver, hull, f.main, main, depth, plates, f.masks);
  int nearer = 0;
  for (int v = 0; v < depth.rows; ++v)
    for (int u = 0; u < depth.cols; ++u)
      nearer += std::isfinite(depth.at<float>(v, u)) && carved.at<float>(v, u) < depth.at<float>(v, u);
  EXPECT_EQ(nearer, 0);
}

// What `previz carve --refine` does on a take without mattes: every silhouette keyed from its
// plate (carving/keyer.h, no clean plate), the main camera's too. The keyed main silhouette
// misses some actor pixels (their depth is +inf: "behind" fails there for the hull as well).
// Measured at t = 4 s (hull / photoHullDepth): 10 cm in front 98.38 / 99.78 %, 10 cm behind
// 99.27 / 99.15 %: as with the true masks. (Before the air search and seen_veto, the keyed
// t = 7 s and t = 2.5 s frames, with witness_stride 1, gave 91.58 / 95.41 % and 92.90 / 99.21 %
// in front, 99.26 / 99.15 % behind: also as with the true masks.)
TEST(RefineDepth, KeyedSilhouettesOrderTheActorAsTheTrueMasksDo) {
  const PlateFrame f = makePlateFrame(4.0);
  std::vector<cv::Mat> keyed;
  for (const Plate& p : f.witness_plates) keyed.push_back(Keyer().key(p.bgr).silhouette);
  const cv::Mat main_key = Keyer().key(f.main_plate.bgr).silhouette;
  HullOptions o;
  o.voxel_m = 0.005;
  Carver carver(f.studio.witnesses, o);
  Silhouettes s;
  s.masks = keyed;
  const VisualHull hull = carver.carve(s);
  const cv::Mat hull_depth = carver.depth(hull, f.studio.main, main_key);
  const cv::Mat photo = photoHullDepth(carver, hull, f.studio.main, f.main_plate, hull_depth,
                                       f.witness_plates, keyed);
  const cv::Mat& truth = f.studio.main_raster.depth;
  const Ordering h = ordering(hull_depth, truth), p = ordering(photo, truth);
  for (int i = 0; i < 3; ++i)
    std::printf("  keyed, plane %2.0f cm in front: hull %.3f %%, photo hull %.3f %% | behind: hull %.3f %%, "
                "photo hull %.3f %%\n",
                100 * kPlanes[i], 100 * h.front[i], 100 * p.front[i], 100 * h.behind[i], 100 * p.behind[i]);
  expectBeyondHull(hull_depth, photo, "photoHullDepth, keyed");
  EXPECT_LT(h.front[1], 0.99);
  EXPECT_GE(p.front[1], 0.995);
  EXPECT_GE(p.behind[1], h.behind[1] - 0.005);
  EXPECT_GE(p.behind[1], 0.99);
}

}  // namespace
}  // namespace previz::carving
