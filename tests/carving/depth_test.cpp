// Main-view depth from the visual hull, against the exact visual hull of the same silhouettes
// (hull_fixture.h: independent point test, 1 mm march + bisection) and against the true actor
// surface. Silhouettes are the true actor mesh rasterized through each camera's true lens; the
// witnesses are at their full 1280x720, the main camera at 960x540 (half size, same lens) to
// keep the reference affordable on 2 cores.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <string>

#include <opencv2/imgproc.hpp>

#include "carving/hull.h"
#include "core/camera_io.h"
#include "core/error.h"
#include "hull_fixture.h"

namespace previz::carving {
namespace {

using namespace previz::carving::test;

constexpr int kMainW = 960, kMainH = 540;

const StudioFrame& frame() {
  static const StudioFrame f = makeStudioFrame(4.0, kMainW, kMainH);
  return f;
}

HullOptions hullOptions() {
  HullOptions o;
  o.voxel_m = 0.005;
  return o;
}

Eigen::AlignedBox3d searchBox(const StudioFrame& f, const HullOptions& o) {
  Eigen::AlignedBox3d box = f.actor_bounds;
  box.min() -= Eigen::Vector3d::Constant(0.3);
  box.max() += Eigen::Vector3d::Constant(0.3);
  return box.intersection(o.volume);
}

ReferenceHull reference(const StudioFrame& f, const std::vector<cv::Mat>& masks, const HullOptions& o) {
  ReferenceHull ref;
  ref.cameras = f.witnesses;
  ref.masks = masks;
  ref.k = o.k;
  ref.min_views = o.min_views;
  ref.volume = o.volume;
  return ref;
}

// The reference depth of the 8-camera hull (k = 0), computed once per process.
const cv::Mat& fullReferenceDepth() {
  static const cv::Mat d = [] {
    const StudioFrame& f = frame();
    const HullOptions o = hullOptions();
    return referenceDepthMap(reference(f, f.masks, o), f.main, f.main_raster.mask, searchBox(f, o));
  }();
  return d;
}

TEST(HullDepth, WithinThreeMillimetresOfExactHull) {
  const StudioFrame& f = frame();
  const HullOptions o = hullOptions();
  Carver carver(f.witnesses, o);
  Silhouettes s;
  s.masks = f.masks;
  const VisualHull hull = carver.carve(s);
  const auto t0 = std::chrono::steady_clock::now();
  const cv::Mat depth = carver.depth(hull, f.main, f.main_raster.mask);
  const double depth_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::printf("carve %.1f ms, %lld surface + %lld inside cells; depth %.1f ms (first call, "
              "ray table included)\n",
              hull.stats.ms, hull.stats.surface_cells, hull.stats.inside_cells, depth_ms);

  const DepthErrors e = compareDepth(depth, fullReferenceDepth(), f.main_raster.mask);
  printErrors("depth vs exact hull", e);
  EXPECT_LE(e.median(), 0.003);
  EXPECT_LE(e.p(0.95), 0.015);
  EXPECT_GT(e.both_finite, 5000);

  // What users feel: the hull against the true actor surface (the hull is a superset, so its
  // depth is nearer). The rasterized truth is checked against ray-mesh intersection on a sample.
  const DepthErrors t = compareDepth(depth, f.main_raster.depth, f.main_raster.mask);
  printErrors("depth vs true actor surface", t);
  int checked = 0;
  double worst = 0;
  for (int v = 0; v < kMainH; v += 17)
    for (int u = 0; u < kMainW; u += 13) {
      if (!f.main_raster.mask.at<std::uint8_t>(v, u)) continue;
      const auto ray = pixelRay(f.main, u, v);
      ASSERT_TRUE(ray);
      const Eigen::Vector3d unit = ray->dir.normalized();
      const double t_hit = synth::intersectMesh(f.actor, synth::Ray{ray->origin, unit});
      if (!std::isfinite(t_hit)) continue;  // pixel centre on a mesh edge: rasterizer inclusive
      const double z_true = t_hit / ray->dir.norm();
      worst = std::max(worst, std::abs(z_true - f.main_raster.depth.at<float>(v, u)));
      ++checked;
    }
  std::printf("rasterized truth vs intersectMesh: %d pixels, worst %.3f mm\n", checked, 1e3 * worst);
  EXPECT_GE(checked, 40);
  EXPECT_LT(worst, 0.002);
}

// Issue 34: half the witnesses fisheye (Kannala-Brandt, 160 degrees diagonal, f ~500 px where
// the others have ~900 px), the rest Brown-Conrady: the carve through both lens models against
// the exact hull of the same silhouettes (its own reference), with the bounds above. The
// footprints through a fisheye are bounded as through any lens (lensBounds' numerical second
// derivative over the valid disc): the hull stays a superset, checked against the true surface.
TEST(HullDepth, MixedFisheyeAndBrownWitnessesWithinThreeMillimetresOfExactHull) {
  const StudioFrame f = makeStudioFrame(4.0, kMainW, kMainH, false, nullptr, 8, 4);
  ASSERT_EQ(f.witnesses[0].camera.dist.model, LensModel::kKannalaBrandt);
  ASSERT_EQ(f.witnesses[7].camera.dist.model, LensModel::kBrownConrady);
  const HullOptions o = hullOptions();
  Carver carver(f.witnesses, o);
  Silhouettes s;
  s.masks = f.masks;
  const VisualHull hull = carver.carve(s);
  const cv::Mat depth = carver.depth(hull, f.main, f.main_raster.mask);
  const cv::Mat reference_depth =
      referenceDepthMap(reference(f, f.masks, o), f.main, f.main_raster.mask, searchBox(f, o));
  const DepthErrors e = compareDepth(depth, reference_depth, f.main_raster.mask);
  printErrors("4 fisheye + 4 Brown witnesses: depth vs exact hull", e);
  EXPECT_LE(e.median(), 0.003);
  EXPECT_LE(e.p(0.95), 0.015);
  EXPECT_GT(e.both_finite, 5000);
  // Conservative footprints stay conservative: the carve cuts no more into the exact hull of the
  // same silhouettes than it does through Brown lenses alone. Against the true
  // surface the hull loses what the silhouettes lose: a fisheye witness at f ~500 px samples the
  // actor at about half the resolution of the others, and thin parts under a pixel wide (fingers)
  // drop out of its mask (printed: pixels behind the true surface, beside the all-Brown rig's).
  int behind_exact = 0, behind_true = 0, behind_true_brown = 0, behind_exact_brown = 0, both = 0;
  const cv::Mat& brown_depth = [] {
    static cv::Mat d;
    const StudioFrame& b = frame();
    Carver c(b.witnesses, hullOptions());
    Silhouettes sb;
    sb.masks = b.masks;
    d = c.depth(c.carve(sb), b.main, b.main_raster.mask);
    return d;
  }();
  for (int v = 0; v < depth.rows; ++v)
    for (int u = 0; u < depth.cols; ++u) {
      const float a = depth.at<float>(v, u), r = reference_depth.at<float>(v, u), t = f.main_raster.depth.at<float>(v, u);
      if (std::isfinite(a) && std::isfinite(r)) behind_exact += a > r + 0.001f;
      const float bd0 = brown_depth.at<float>(v, u), br = fullReferenceDepth().at<float>(v, u);
      if (std::isfinite(bd0) && std::isfinite(br)) behind_exact_brown += bd0 > br + 0.001f;
      if (!std::isfinite(a) || !std::isfinite(t)) continue;
      ++both;
      behind_true += a > t + 0.005f;
      const float bd = brown_depth.at<float>(v, u);
      behind_true_brown += std::isfinite(bd) && bd > t + 0.005f;
    }
  std::printf("pixels behind the exact hull by > 1 mm: %d (all-Brown rig: %d); behind the true surface by > 5 mm: "
              "%d of %d (all-Brown rig: %d)\n",
              behind_exact, behind_exact_brown, behind_true, both, behind_true_brown);
  // The all-Brown carve leaves 32 pixels (0.3 %) behind its exact hull by > 1 mm (cells of 5 mm
  // at thin parts, within the p99 above): the fisheye rig may not do worse than 0.5 %.
  EXPECT_LE(behind_exact, both / 200);
}

// Item 2: a virtual plane 5, 10, 20 cm in front of / behind the true surface, per pixel: is the
// actor put on the right side of it (what depth compositing against CG needs)? The visual hull
// is a superset of the actor, so in-front planes are the hard case, and how hard depends on the
// rig: this studio leaves a gap in the witness ring around the main camera's line of sight
// (datasets/rigs.h), so nothing carves the hull's front as the main camera sees it. The
// implementation must match the exact hull's fraction; for the hull depth the 99.5 % goal at
// 10 cm is asserted at 20 cm, where this rig's exact hull reaches it (see the printed figures).
// The refined depth (carving/refine.h) reaches it at 10 cm: tests/carving/refine_test.cpp.
TEST(HullDepth, OrdersActorAgainstPlanesLikeTheExactHull) {
  const StudioFrame& f = frame();
  Carver carver(f.witnesses, hullOptions());
  Silhouettes s;
  s.masks = f.masks;
  const cv::Mat depth = carver.depth(carver.carve(s), f.main, f.main_raster.mask);
  const cv::Mat& truth = f.main_raster.depth;
  for (const double d : {0.05, 0.10, 0.20}) {
    const double front = orderedFraction(depth, truth, d, true);
    const double behind = orderedFraction(depth, truth, d, false);
    const double exact_front = orderedFraction(fullReferenceDepth(), truth, d, true);
    const double exact_behind = orderedFraction(fullReferenceDepth(), truth, d, false);
    std::printf("plane %2.0f cm in front: %.3f %% correct (exact hull %.3f %%); %2.0f cm behind: "
                "%.3f %% (exact hull %.3f %%)\n",
                100 * d, 100 * front, 100 * exact_front, 100 * d, 100 * behind, 100 * exact_behind);
    EXPECT_NEAR(front, exact_front, 0.002) << "d = " << d;
    EXPECT_NEAR(behind, exact_behind, 0.002) << "d = " << d;
    EXPECT_GE(behind, 0.995) << "d = " << d;
    if (d >= 0.20) {
      EXPECT_GE(front, 0.995) << "d = " << d;
    }
  }
}

// A coarser carve's main-view depth must still be the exact hull of the masks, the rays finding
// the crossing below the cell size: no pixel with depth in one only, 99 % within 0.5 mm, and the
// in-front ordering against the truth as the exact hull's.
void expectExactHullDepth(const HullOptions& o, const char* label) {
  const StudioFrame& f = frame();
  Carver carver(f.witnesses, o);
  Silhouettes s;
  s.masks = f.masks;
  const cv::Mat depth = carver.depth(carver.carve(s), f.main, f.main_raster.mask);
  const DepthErrors e = compareDepth(depth, fullReferenceDepth(), f.main_raster.mask);
  printErrors((std::string(label) + ": depth vs exact hull").c_str(), e);
  EXPECT_EQ(e.only_ours + e.only_ref, 0);
  EXPECT_LE(e.p(0.99), 0.0005);
  const cv::Mat& truth = f.main_raster.depth;
  for (const double d : {0.05, 0.10, 0.20}) {
    EXPECT_NEAR(orderedFraction(depth, truth, d, true), orderedFraction(fullReferenceDepth(), truth, d, true),
                0.003)
        << "d = " << d;
    EXPECT_NEAR(orderedFraction(depth, truth, d, false), orderedFraction(fullReferenceDepth(), truth, d, false),
                0.002)
        << "d = " << d;
  }
}

// 1 cm cells (the live loop's until it went to 2 cm) with the library's step (half a cell).
// Measured: 99 % of pixels within 0.07 mm of the exact hull (0.02 mm at 5 mm); the 10 cm
// in-front ordering 98.41 % against the exact hull's 98.37 % (1 cm misses a few hull slivers
// thinner than its 5 mm samples, which lie in front of the actor).
TEST(HullDepth, OneCentimetreCellsStillGiveTheExactHullDepth) {
  HullOptions o = hullOptions();
  o.voxel_m = 0.01;
  expectExactHullDepth(o, "1 cm cells");
}

// The live loop carves at 2 cm and samples the rays every 2.5 mm (live/frame_loop.h
// liveHullOptions): the carve only guides the rays; the step, not the cell, decides which thin
// slivers a ray can miss. Measured: p99 0.03 mm; with the library's step (1 cm) p99 11 mm and 4
// pixels without depth.
TEST(HullDepth, TwoCentimetreCellsWithFineRaySamplesGiveTheExactHullDepth) {
  HullOptions o = hullOptions();
  o.voxel_m = 0.02;
  o.depth_step_m = 0.0025;
  expectExactHullDepth(o, "2 cm cells, 2.5 mm ray samples");
}

TEST(HullDepth, RejectsANegativeRayStep) {
  HullOptions o;
  o.depth_step_m = -0.001;
  EXPECT_THROW(o.validate(), previz::Error);
}

// Item 3: one witness dropped (no frame), one with a corrupt silhouette (the half of the actor
// left of its silhouette's centre blacked out).
struct DegradedInput {
  std::vector<cv::Mat> masks;
  int dropped = 2, corrupt = 5;
};
DegradedInput degradedInput(const StudioFrame& f) {
  DegradedInput in;
  in.masks = f.masks;
  in.masks[in.dropped] = cv::Mat();
  cv::Mat& m = in.masks[in.corrupt];
  m = m.clone();
  const cv::Rect box = cv::boundingRect(m);
  m(cv::Rect(0, 0, box.x + box.width / 2, m.rows)).setTo(0);
  return in;
}

TEST(HullDepth, CarvesOnWithDroppedAndFlaggedCameras) {
  const StudioFrame& f = frame();
  const HullOptions o = hullOptions();  // k = 0
  const DegradedInput in = degradedInput(f);
  Carver carver(f.witnesses, o);
  Silhouettes s;
  s.masks = in.masks;
  s.dropped.assign(f.witnesses.size(), "");
  s.dropped[in.corrupt] = "corrupt frame (flagged by the caller)";
  const VisualHull hull = carver.carve(s);
  ASSERT_EQ(hull.stats.cameras_dropped.size(), 2u);
  EXPECT_EQ(hull.stats.cameras_dropped[0], f.witnesses[in.dropped].camera.name);
  EXPECT_EQ(hull.stats.cameras_dropped[1], f.witnesses[in.corrupt].camera.name);
  EXPECT_EQ(hull.stats.drop_reasons[0], "no silhouette (empty mask)");
  EXPECT_EQ(hull.stats.drop_reasons[1], s.dropped[in.corrupt]);
  EXPECT_EQ(hull.stats.cameras_used.size(), f.witnesses.size() - 2);
  const cv::Mat depth = carver.depth(hull, f.main, f.main_raster.mask);

  // Against the exact hull of the 6 cameras used (the implementation's own accuracy) ...
  std::vector<cv::Mat> used = in.masks;
  used[in.corrupt] = cv::Mat();
  const cv::Mat ref6 = referenceDepthMap(reference(f, used, o), f.main, f.main_raster.mask, searchBox(f, o));
  const DepthErrors e6 = compareDepth(depth, ref6, f.main_raster.mask);
  printErrors("6 cameras vs exact 6-camera hull", e6);
  EXPECT_LE(e6.median(), 0.003);
  EXPECT_LE(e6.p(0.95), 0.015);
  // ... and against the 8-camera hull of item 1: losing two views costs at most 2x its bounds.
  const DepthErrors e8 = compareDepth(depth, fullReferenceDepth(), f.main_raster.mask);
  printErrors("6 cameras vs exact 8-camera hull", e8);
  EXPECT_LE(e8.median(), 2 * 0.003);
  EXPECT_LE(e8.p(0.95), 2 * 0.015);
}

// Fraction of true actor pixels whose hull depth is at most 1 cm behind the true surface: the
// hull still contains the actor there (it may not be carved through).
double containedFraction(const cv::Mat& depth, const cv::Mat& truth) {
  return orderedFraction(depth, truth, 0.01, false);
}

TEST(HullDepth, KOfNToleratesOneCorruptSilhouette) {
  const StudioFrame& f = frame();
  const DegradedInput in = degradedInput(f);
  HullOptions o = hullOptions();
  Silhouettes s;
  s.masks = in.masks;  // the corrupt camera is NOT flagged
  // k = 0 trusts the corrupt view and carves half the actor away (so this test can fail).
  double contained_k0 = 0;
  {
    Carver carver(f.witnesses, o);
    const cv::Mat depth = carver.depth(carver.carve(s), f.main, f.main_raster.mask);
    contained_k0 = containedFraction(depth, f.main_raster.depth);
  }
  o.k = 1;
  Carver carver(f.witnesses, o);
  const VisualHull hull = carver.carve(s);
  ASSERT_EQ(hull.stats.cameras_dropped.size(), 1u);
  const cv::Mat depth = carver.depth(hull, f.main, f.main_raster.mask);
  const double contained_k1 = containedFraction(depth, f.main_raster.depth);
  std::printf("actor pixels whose hull depth is within 1 cm behind the true surface: k = 0 %.2f %%, "
              "k = 1 %.2f %%\n", 100 * contained_k0, 100 * contained_k1);
  EXPECT_LT(contained_k0, 0.95);
  EXPECT_GE(contained_k1, 0.99);
  // Accuracy: the exact hull of the same silhouettes under the same rule (k = 1).
  const cv::Mat ref = referenceDepthMap(reference(f, in.masks, o), f.main, f.main_raster.mask,
                                        searchBox(f, o));
  const DepthErrors e = compareDepth(depth, ref, f.main_raster.mask);
  printErrors("k = 1 with the corrupt view vs its exact k = 1 hull", e);
  EXPECT_LE(e.median(), 0.003);
  EXPECT_LE(e.p(0.95), 0.015);
  // What k = 1 costs (information): a looser hull than the 8 clean views' k = 0 hull.
  printErrors("k = 1 with the corrupt view vs the exact 8-camera k = 0 hull",
              compareDepth(depth, fullReferenceDepth(), f.main_raster.mask));
  printErrors("k = 1 with the corrupt view vs the true surface",
              compareDepth(depth, f.main_raster.depth, f.main_raster.mask));
}

// Item 5: cameras handed over as 3x4 projection matrices (no distortion) carve like rig.json
// cameras. An undistorted-lens rig, so that both describe the same cameras exactly.
TEST(HullDepth, ProjectionMatrixCamerasCarveLikeRigCameras) {
  static const StudioFrame f = makeStudioFrame(4.0, kMainW, kMainH, /*undistorted=*/true);
  std::vector<RigCamera> from_p;
  for (const RigCamera& c : f.witnesses) {
    RigCamera p = rigCameraFromProjection(projectionMatrix(c), c.camera.width, c.camera.height,
                                          c.camera.name);
    from_p.push_back(p);
  }
  const HullOptions o = hullOptions();
  Silhouettes s;
  s.masks = f.masks;
  Carver rig_carver(f.witnesses, o), p_carver(from_p, o);
  const VisualHull rig_hull = rig_carver.carve(s), p_hull = p_carver.carve(s);
  const cv::Mat rig_depth = rig_carver.depth(rig_hull, f.main, f.main_raster.mask);
  const cv::Mat p_depth = p_carver.depth(p_hull, f.main, f.main_raster.mask);
  const cv::Mat ref =
      referenceDepthMap(reference(f, f.masks, o), f.main, f.main_raster.mask, searchBox(f, o));
  const DepthErrors e = compareDepth(p_depth, ref, f.main_raster.mask);
  printErrors("P-matrix cameras vs exact hull", e);
  EXPECT_LE(e.median(), 0.003);
  EXPECT_LE(e.p(0.95), 0.015);
  EXPECT_GT(e.both_finite, 5000);
  const DepthErrors between = compareDepth(p_depth, rig_depth, f.main_raster.mask);
  printErrors("P-matrix cameras vs rig cameras", between);
  EXPECT_LE(between.p(0.99), 0.001);
  std::printf("cells: rig %lld surface / P %lld surface\n", rig_hull.stats.surface_cells,
              p_hull.stats.surface_cells);
}

}  // namespace
}  // namespace previz::carving
