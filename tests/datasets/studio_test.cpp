// The synthetic studio's content: actor geometry and motion, stage shading, the tagged prop,
// the CG set layout and the mesh files. Truth is the analytic geometry in datasets/studio_*.cpp.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>
#include <gtest/gtest.h>

#include "core/error.h"
#include "datasets/detail/studio_detail.h"
#include "datasets/studio.h"
#include "scratch.h"

namespace previz::synth {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;

StudioConfig defaultConfig() { return StudioConfig{}; }

fs::path tmpDir(const std::string& name) {
  return test::scratchDir("studio_test", name);
}

// Signed distance from p to a capsule's surface.
double capsuleDistance(const detail::Capsule& c, const Eigen::Vector3d& p) {
  const Eigen::Vector3d ba = c.b - c.a;
  const double len2 = ba.squaredNorm();
  const double h = len2 > 0 ? std::clamp((p - c.a).dot(ba) / len2, 0.0, 1.0) : 0.0;
  return (p - c.a - h * ba).norm() - c.r;
}

// Distance from the ray (origin, unit dir, t >= 0) to the capsule's surface (negative: hits).
double rayCapsuleClearance(const Ray& ray, const detail::Capsule& c) {
  double s, t;
  const double far = 100.0;
  const double d = detail::segmentSegmentDistance(ray.origin, ray.origin + far * ray.dir, c.a, c.b, s, t);
  return d - c.r;
}

TEST(ActorMesh, MatchesAnalyticSurfaceWithinOneMillimetreAlongRays) {
  // Truth: the analytic capsules that Scene::trace intersects. The mesh lies inside them (its
  // vertices are on the surface of convex parts), at most 0.3 mm deep, so a ray whose first
  // analytic hit meets the surface at |cos| >= 0.3 must hit the mesh within 0.3 / 0.3 = 1 mm
  // of it; a ray that passes > 1 mm from every capsule must miss both.
  const Studio studio(defaultConfig());
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<double> gauss;
  double max_dt = 0;
  int compared = 0, misses_checked = 0;
  for (double time : {0.7, 3.3, 5.2, 8.6}) {
    const detail::ActorPose pose = detail::actorPoseAt(studio.config(), time);
    const TriangleMesh mesh = studio.actorMesh(time);
    const Scene scene = studio.sceneAt(time, kLayerActor);
    for (int i = 0; i < 60; ++i) {
      // Aim at a random point on a random part from a random direction 3 m away.
      const auto& c = pose.parts[static_cast<size_t>(uni(rng) * detail::kActorPartCount) % detail::kActorPartCount];
      const Eigen::Vector3d on_axis = c.a + uni(rng) * (c.b - c.a);
      Eigen::Vector3d n(gauss(rng), gauss(rng), gauss(rng));
      n.normalize();
      const Eigen::Vector3d target = on_axis + c.r * n;
      Eigen::Vector3d from(gauss(rng), gauss(rng), gauss(rng));
      from.normalize();
      if (from.dot(n) < 0) from = -from;
      Ray ray;
      ray.origin = target + 3.0 * from;
      ray.dir = -from;
      Hit hit;
      const bool analytic = scene.trace(ray, hit);
      const double t_mesh = intersectMesh(mesh, ray);
      if (!analytic) {
        ADD_FAILURE() << "ray aimed at the surface missed the actor";
        continue;
      }
      EXPECT_EQ(hit.cls, ObjectClass::kActor);
      if (std::abs(hit.normal.dot(ray.dir)) < 0.3) continue;  // near a silhouette
      ASSERT_TRUE(std::isfinite(t_mesh)) << "mesh missed where the analytic surface is hit";
      max_dt = std::max(max_dt, std::abs(t_mesh - hit.t));
      ++compared;
    }
    // Rays through the actor's bounding box that clear every capsule by > 1 mm.
    const Eigen::AlignedBox3d box = studio.actorBounds(time);
    for (int i = 0; i < 150; ++i) {
      const Eigen::Vector3d target = box.min() + (box.max() - box.min()).cwiseProduct(
                                                     Eigen::Vector3d(uni(rng), uni(rng), uni(rng)));
      Eigen::Vector3d from(gauss(rng), gauss(rng), gauss(rng));
      Ray ray;
      ray.origin = target + 3.0 * from.normalized();
      ray.dir = -from.normalized();
      double clearance = 1e9;
      for (const auto& c : pose.parts) clearance = std::min(clearance, rayCapsuleClearance(ray, c));
      if (clearance <= 1e-3) continue;
      Hit hit;
      EXPECT_FALSE(scene.trace(ray, hit));
      EXPECT_FALSE(std::isfinite(intersectMesh(mesh, ray)));
      ++misses_checked;
    }
  }
  EXPECT_GE(compared, 150);
  EXPECT_GE(misses_checked, 100);
  EXPECT_LE(max_dt, 1e-3);
  std::printf("[ actor mesh ] %d hits compared, max |t_mesh - t_analytic| = %.3f mm; %d misses agree\n",
              compared, max_dt * 1e3, misses_checked);
}

TEST(ActorMesh, PartsAreClosedOutwardAndWithinPointThreeMillimetres) {
  // Truth: each part's capsule. Every vertex lies on it, every triangle's centroid and edge
  // midpoints within 0.3 mm inside it (the sagitta budget), every edge is shared by exactly
  // two triangles (closed), faces wind counter-clockwise seen from outside.
  const Studio studio(defaultConfig());
  const double time = 5.4;  // arms raised
  const detail::ActorPose pose = detail::actorPoseAt(studio.config(), time);
  size_t total_vertices = 0, total_faces = 0;
  double max_vertex_err = 0, max_depth = 0, min_winding = 1;
  for (const auto& c : pose.parts) {
    const TriangleMesh m = detail::capsuleMesh(c, 0.14e-3);
    total_vertices += m.vertices.size();
    total_faces += m.faces.size();
    std::map<std::pair<int, int>, int> edges;
    for (size_t i = 0; i < m.vertices.size(); ++i) {
      const Eigen::Vector3d v = m.vertices[i].cast<double>();
      max_vertex_err = std::max(max_vertex_err, std::abs(capsuleDistance(c, v)));
      EXPECT_NEAR(m.normals[i].norm(), 1.0, 1e-5);
    }
    for (const auto& f : m.faces) {
      const Eigen::Vector3d a = m.vertices[f[0]].cast<double>(), b = m.vertices[f[1]].cast<double>(),
                            d = m.vertices[f[2]].cast<double>();
      for (const Eigen::Vector3d& p : {Eigen::Vector3d((a + b + d) / 3), Eigen::Vector3d((a + b) / 2),
                                       Eigen::Vector3d((b + d) / 2), Eigen::Vector3d((a + d) / 2)})
        max_depth = std::max(max_depth, -capsuleDistance(c, p));
      const Eigen::Vector3d fn = (b - a).cross(d - a);
      if (fn.norm() > 1e-12) {
        const Eigen::Vector3d vn = (m.normals[f[0]] + m.normals[f[1]] + m.normals[f[2]]).cast<double>();
        min_winding = std::min(min_winding, fn.normalized().dot(vn.normalized()));
      }
      for (int k = 0; k < 3; ++k) {
        const int i0 = f[k], i1 = f[(k + 1) % 3];
        edges[{std::min(i0, i1), std::max(i0, i1)}]++;
      }
    }
    for (const auto& [edge, count] : edges) ASSERT_EQ(count, 2) << "open or non-manifold edge";
  }
  const TriangleMesh all = studio.actorMesh(time);
  EXPECT_EQ(all.vertices.size(), total_vertices);
  EXPECT_EQ(all.faces.size(), total_faces);
  EXPECT_LE(max_vertex_err, 2e-6);  // float storage of ~2 m coordinates
  EXPECT_LE(max_depth, 0.3e-3);
  EXPECT_GT(min_winding, 0.9);
  std::printf("[ actor mesh ] %zu vertices, %zu faces; vertices on surface to %.2g m, deepest "
              "chord %.3f mm, min cos(face, vertex normals) %.3f\n",
              total_vertices, total_faces, max_vertex_err, max_depth * 1e3, min_winding);
}

TEST(Actor, WalksTurnsOnTheSpotRaisesArmsAndStaysOnTheFloor) {
  const Studio studio(defaultConfig());
  const double T = studio.config().take_duration_s;
  const int n = 500;
  std::vector<detail::ActorPose> poses;
  for (int i = 0; i <= n; ++i) poses.push_back(detail::actorPoseAt(studio.config(), T * i / n));

  double max_travel = 0, min_part_z = 1e9, min_foot_z = 1e9, max_hand_over_head = -1e9;
  double path = 0, max_on_spot_turn = 0, min_knee_chord = 1e9, heading_span = 0;
  int foot_contact_switches = 0, last_contact = -1;
  for (int i = 0; i <= n; ++i) {
    const auto& p = poses[i];
    max_travel = std::max(max_travel, (p.pelvis - poses[0].pelvis).head<2>().norm());
    if (i > 0) path += (p.pelvis - poses[i - 1].pelvis).head<2>().norm();
    double lowest_foot = 1e9;
    for (int k = 0; k < detail::kActorPartCount; ++k) {
      const auto& c = p.parts[k];
      const double z = std::min(c.a.z(), c.b.z()) - c.r;
      if (k == detail::kFootL || k == detail::kFootR) {
        min_foot_z = std::min(min_foot_z, z);
        lowest_foot = std::min(lowest_foot, z);
      } else {
        min_part_z = std::min(min_part_z, z);
      }
    }
    EXPECT_NEAR(lowest_foot, 0.0, 1e-9) << "the actor must stand on the floor at t index " << i;
    // Which foot carries the weight (lower): alternates while walking.
    const auto& fl = p.parts[detail::kFootL];
    const auto& fr = p.parts[detail::kFootR];
    const int contact = std::min(fl.a.z(), fl.b.z()) < std::min(fr.a.z(), fr.b.z()) - 0.005 ? 0
                        : std::min(fr.a.z(), fr.b.z()) < std::min(fl.a.z(), fl.b.z()) - 0.005 ? 1 : -1;
    if (contact >= 0 && last_contact >= 0 && contact != last_contact) ++foot_contact_switches;
    if (contact >= 0) last_contact = contact;
    const double head_top = p.parts[detail::kHead].a.z() + p.parts[detail::kHead].r;
    max_hand_over_head = std::max(max_hand_over_head, std::min(p.parts[detail::kHandL].a.z(),
                                                               p.parts[detail::kHandR].a.z()) - head_top);
    for (int k : {detail::kLowerLegL, detail::kLowerLegR}) {
      const auto& thigh = p.parts[k - 1];
      const auto& shank = p.parts[k];
      min_knee_chord = std::min(min_knee_chord, (shank.b - thigh.a).norm());
    }
    heading_span = std::max(heading_span, std::abs(std::remainder(p.heading - poses[0].heading, 2 * kPi)));
    // On-the-spot turn: heading change over 1 s while the pelvis moves < 3 cm.
    const int j = i + n / 10;
    if (j <= n && (poses[j].pelvis - p.pelvis).head<2>().norm() < 0.03)
      max_on_spot_turn = std::max(max_on_spot_turn, std::abs(std::remainder(poses[j].heading - p.heading, 2 * kPi)));
  }
  EXPECT_GT(max_travel, 2.0);
  EXPECT_GT(path, 5.0);
  EXPECT_GT(max_on_spot_turn, 60 * kPi / 180);
  EXPECT_GT(heading_span, kPi / 2);
  EXPECT_GT(max_hand_over_head, 0.1);  // hands at least 10 cm above the top of the head
  EXPECT_GE(min_part_z, 0.005);        // no part but the feet within 5 mm of the floor
  EXPECT_GE(min_foot_z, -1e-9);
  EXPECT_LT(min_knee_chord, 0.80);     // knees bend (straight leg: 0.85 m hip to ankle)
  EXPECT_GE(foot_contact_switches, 8); // left/right stance alternates: several steps
  std::printf("[ actor ] travel %.2f m, path %.2f m, on-spot turn %.0f deg, heading span %.0f deg, "
              "hands over head %.2f m, lowest non-foot part %.3f m, %d stance switches\n",
              max_travel, path, max_on_spot_turn * 180 / kPi, heading_span * 180 / kPi,
              max_hand_over_head, min_part_z, foot_contact_switches);
}

TEST(Actor, MeasuresAboutOneSeventyFiveMetresStanding) {
  const Studio studio(defaultConfig());
  const double standing = 0.56 * studio.config().take_duration_s;  // stopped, arms about down
  const auto pose = detail::actorPoseAt(studio.config(), 0.485 * studio.config().take_duration_s);
  EXPECT_NEAR(pose.speed, 0.0, 0.05);
  const Eigen::AlignedBox3d box = studio.actorBounds(0.485 * studio.config().take_duration_s);
  EXPECT_NEAR(box.max().z(), 1.75, 0.03);
  EXPECT_GT(studio.actorBounds(standing).max().z(), 1.9);  // arms up
}

TEST(Prop, NeverComesWithinFiveCentimetresOfTheActor) {
  // Conservative: the crate is replaced by its bounding sphere (half-diagonal).
  const Studio studio(defaultConfig());
  const double T = studio.config().take_duration_s;
  const double crate_r = 0.5 * studio.prop().box_size_m.norm();
  double min_gap = 1e9;
  for (int i = 0; i <= 1000; ++i) {
    const double t = T * i / 1000;
    const Eigen::Vector3d c = studio.T_world_prop(t).translation();
    const auto pose = detail::actorPoseAt(studio.config(), t);
    for (const auto& part : pose.parts) min_gap = std::min(min_gap, capsuleDistance(part, c) - crate_r);
    EXPECT_GE(c.z() - crate_r, 0.5);  // carried, never dragged on the floor
  }
  EXPECT_GT(min_gap, 0.05);
  std::printf("[ prop ] min gap to the actor %.2f m (crate as its bounding sphere)\n", min_gap);
}

// Distance from a capsule to an axis-aligned box (sampled along the axis every <= 2 mm).
double capsuleBoxGap(const detail::Capsule& c, const Eigen::AlignedBox3d& box) {
  const int n = 1 + static_cast<int>((c.b - c.a).norm() / 0.002);
  double best = 1e9;
  for (int i = 0; i <= n; ++i) {
    const Eigen::Vector3d p = c.a + (c.b - c.a) * (static_cast<double>(i) / n);
    best = std::min(best, std::sqrt(box.squaredExteriorDistance(p)) - c.r);
  }
  return best - 0.001;  // sampling slack
}

TEST(CgSet, ActorPassesBehindAndInFrontOfThePillarWithoutTouchingTheSet) {
  // The main camera sits at about (0, -6, 1.6) looking +y (render helper). The pillar must
  // hide the actor at some time and the actor must cover the pillar at another; and the
  // actor's capsules never enter the pillar or the table (boxes from studio_stage.cpp).
  const Studio studio(defaultConfig());
  const double T = studio.config().take_duration_s;
  const Eigen::Vector3d camera(0, -6, 1.6);
  const Eigen::AlignedBox3d pillar(Eigen::Vector3d(0.05, -0.85, 0), Eigen::Vector3d(0.55, -0.35, 3.0));
  const Eigen::AlignedBox3d table(Eigen::Vector3d(-1.9, -0.65, 0), Eigen::Vector3d(-0.7, 0.05, 0.8));
  int behind = 0, in_front = 0;
  double min_gap = 1e9;
  for (int i = 0; i <= 200; ++i) {
    const double t = T * i / 200;
    const Scene scene = studio.sceneAt(t, kLayerActor | kLayerCg);
    const auto pose = detail::actorPoseAt(studio.config(), t);
    const Eigen::Vector3d chest = 0.5 * (pose.parts[detail::kTorso].a + pose.parts[detail::kTorso].b);
    Ray ray{camera, (chest - camera).normalized()};
    Hit hit;
    scene.trace(ray, hit);
    if (hit.cls == ObjectClass::kCg && hit.object == 0) ++behind;
    ray.dir = (Eigen::Vector3d(0.3, -0.6, 1.2) - camera).normalized();
    scene.trace(ray, hit);
    if (hit.cls == ObjectClass::kActor) ++in_front;
    for (const auto& c : pose.parts) min_gap = std::min({min_gap, capsuleBoxGap(c, pillar), capsuleBoxGap(c, table)});
  }
  EXPECT_GE(behind, 3);
  EXPECT_GE(in_front, 3);
  EXPECT_GT(min_gap, 0.05);
  std::printf("[ cg ] chest hidden by the pillar in %d/201 samples, actor over the pillar in %d; "
              "min gap to pillar/table %.2f m\n", behind, in_front, min_gap);
}

TEST(Stage, ShadowUnderTheActorIsDarkerAndStillGreen) {
  // Same floor point with and without the actor: the soft shadow of the key light lowers it;
  // the screen colour keeps its hue (green dominant, channel ratios unchanged).
  const Studio studio(defaultConfig());
  int checked = 0;
  double darkest = 1;
  for (double t : {1.0, 3.0, 5.4, 7.5, 9.0}) {
    const auto pose = detail::actorPoseAt(studio.config(), t);
    const Eigen::Vector3d chest = 0.5 * (pose.parts[detail::kTorso].a + pose.parts[detail::kTorso].b);
    // Where the line from the light centre through the chest meets the floor.
    const Eigen::Vector3d L = detail::kKeyLightCentre;
    const Eigen::Vector3d q = L + (chest - L) * (L.z() / (L.z() - chest.z()));
    const Scene with = studio.sceneAt(t, kLayerStage | kLayerActor);
    const Scene without = studio.sceneAt(t, kLayerStage);
    const Ray down{q + Eigen::Vector3d(0, 0, 0.02), -Eigen::Vector3d::UnitZ()};
    Hit a, b;
    with.trace(down, a);
    without.trace(down, b);
    ASSERT_EQ(a.cls, ObjectClass::kStage);
    ASSERT_EQ(b.cls, ObjectClass::kStage);
    const double ratio = a.rgb.y() / b.rgb.y();
    EXPECT_LT(ratio, 0.8) << "t = " << t;
    EXPECT_GT(ratio, 0.2) << "t = " << t;  // soft studio shadow, not black
    EXPECT_GT(a.rgb.y(), 2.5 * std::max(a.rgb.x(), a.rgb.z()));
    EXPECT_NEAR(a.rgb.x() / a.rgb.y(), b.rgb.x() / b.rgb.y(), 1e-5);
    darkest = std::min(darkest, ratio);
    ++checked;
    // Far from the actor the actor changes nothing.
    const Ray far{Eigen::Vector3d(-3.5, 3.5, 0.02), -Eigen::Vector3d::UnitZ()};
    with.trace(far, a);
    without.trace(far, b);
    EXPECT_EQ(a.rgb, b.rgb);
  }
  EXPECT_EQ(checked, 5);
  std::printf("[ stage ] shadow/lit green ratio down to %.2f\n", darkest);
}

TEST(Stage, CycloramaIsGreenAndUnevenAndTheStudioBeyondIsDark) {
  // Rays from a witness position in every direction: floor, walls and coves are stage (green
  // dominant), everything past the cyclorama's open sides or above its walls is the dark
  // studio (no channel above 0.1, not green dominant). The screen is uneven: its brightness
  // varies by a few percent over the floor.
  StudioConfig config = defaultConfig();
  const Studio studio(config);
  const Scene scene = studio.sceneAt(2.0, kLayerStage);
  const Eigen::Vector3d eye(3.0, -3.0, 2.5);
  int stage = 0, dark = 0;
  double min_g = 1, max_g = 0;
  for (int i = 0; i < 2000; ++i) {
    const double az = 2 * kPi * i / 2000 * 7.0;  // spiral over the sphere
    const double el = -kPi / 2 + kPi * (i + 0.5) / 2000;
    Ray ray{eye, Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el))};
    Hit hit;
    ASSERT_TRUE(scene.trace(ray, hit));
    const Eigen::Vector3d p = ray.origin + hit.t * ray.dir;
    const double h = 0.5 * config.cyc_size_m;
    if (hit.cls == ObjectClass::kStage) {
      ++stage;
      EXPECT_LE(p.x(), h + 1e-6);
      EXPECT_GE(p.y(), -h - 1e-6);
      EXPECT_LE(p.z(), config.wall_height_m + 1e-6);
      EXPECT_GT(hit.rgb.y(), 2.5 * std::max(hit.rgb.x(), hit.rgb.z()));
      EXPECT_LT(hit.normal.dot(ray.dir), 0);
      if (hit.object == 0 && std::hypot(p.x(), p.y()) < 2) {
        min_g = std::min<double>(min_g, hit.rgb.y());
        max_g = std::max<double>(max_g, hit.rgb.y());
      }
    } else {
      ASSERT_EQ(hit.cls, ObjectClass::kStudio);
      ++dark;
      EXPECT_LT(hit.rgb.maxCoeff(), 0.1f);
      EXPECT_LT(hit.rgb.y(), 1.3f * std::max(hit.rgb.x(), hit.rgb.z()));
      // Only where the cyclorama is not: beyond its open sides, over the walls or the floor
      // outside the green square.
      EXPECT_TRUE(p.x() > h - 1e-6 || p.y() < -h + 1e-6 || p.z() > config.wall_height_m - 1e-6 ||
                  std::abs(p.x()) > h - 1e-6 || std::abs(p.y()) > h - 1e-6);
    }
  }
  EXPECT_GT(stage, 700);
  EXPECT_GT(dark, 50);
  EXPECT_GT(max_g / min_g, 1.03);  // uneven
  EXPECT_LT(max_g / min_g, 1.6);   // but a usable screen near the centre
  std::printf("[ stage ] %d stage / %d studio rays; central floor green %.3f .. %.3f\n", stage, dark,
              min_g, max_g);
}

TEST(Stage, CoveJoinsFloorAndWallsWithoutGaps) {
  // Rays swept across the floor/back-wall cove, the floor/left-wall cove and the corner: every
  // one hits the stage on the rounded surface (floor, walls, coves, corner sphere), and
  // consecutive hits are close (no gap, no step).
  const Studio studio(defaultConfig());
  const Scene scene = studio.sceneAt(0, kLayerStage);
  const Eigen::Vector3d eye(0.5, 0.5, 1.5);
  for (const Eigen::Vector3d& target_dir : {Eigen::Vector3d(0.0, 1.0, 0.0), Eigen::Vector3d(-1.0, 0.0, 0.0),
                                            Eigen::Vector3d(-1.0, 1.0, 0.0).normalized()}) {
    Eigen::Vector3d prev = Eigen::Vector3d::Zero();
    bool first = true;
    for (int i = 0; i <= 400; ++i) {
      const double el = -0.5 + 0.5 * i / 400.0;  // from the floor up across the cove
      Ray ray{eye, (target_dir * std::cos(el) + Eigen::Vector3d::UnitZ() * std::sin(el)).normalized()};
      Hit hit;
      ASSERT_TRUE(scene.trace(ray, hit));
      ASSERT_EQ(hit.cls, ObjectClass::kStage);
      const Eigen::Vector3d p = ray.origin + hit.t * ray.dir;
      // On the rounded box: 0.6 m (the cove radius) from the orthant x >= -h + 0.6,
      // y <= h - 0.6, z >= 0.6 (studio_stage.cpp).
      const double h = 0.5 * studio.config().cyc_size_m, rc = 0.6;
      const Eigen::Vector3d c(std::max(p.x(), -h + rc), std::min(p.y(), h - rc), std::max(p.z(), rc));
      EXPECT_NEAR((p - c).norm(), rc, 1e-6);
      if (!first) {
        EXPECT_LT((p - prev).norm(), 0.1);
      }
      prev = p;
      first = false;
    }
  }
}

TEST(Prop, TagsAreOnFiveFacesWithInwardZAndDistinctIds) {
  const Studio studio(defaultConfig());
  const PropSpec& spec = studio.prop();
  ASSERT_EQ(spec.tags.size(), 5u);
  std::vector<int> ids;
  for (const PropTag& tag : spec.tags) {
    ids.push_back(tag.id);
    EXPECT_EQ(tag.family, "tag36h11");
    EXPECT_DOUBLE_EQ(tag.size_m, 0.12);
    const Eigen::Matrix3d R = tag.T_prop_tag.linear();
    EXPECT_NEAR((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
    EXPECT_NEAR(R.determinant(), 1, 1e-12);
    const Eigen::Vector3d centre = tag.T_prop_tag.translation();
    // On a face: one coordinate at +-half the box, z of the tag pointing into the box.
    int axis;
    centre.cwiseAbs().maxCoeff(&axis);
    EXPECT_NEAR(std::abs(centre[axis]), 0.5 * spec.box_size_m[axis], 1e-12);
    EXPECT_NEAR(centre.norm(), 0.5 * spec.box_size_m[axis], 1e-12);
    EXPECT_NEAR(R.col(2).dot(centre.normalized()), -1, 1e-12);
    EXPECT_FALSE(centre.z() < -0.1) << "no tag on the bottom";
  }
  std::sort(ids.begin(), ids.end());
  EXPECT_EQ(ids, (std::vector<int>{0, 1, 2, 3, 4}));
}

TEST(Prop, LibapriltagDecodesEachFaceWithCornersWhereTheTagPoseSays) {
  // Orthographic fronto-parallel render of each face through Scene::trace (4 x 4 supersampled,
  // 0.5 mm pixels: the tag is 240 px). libapriltag must return the face's id with corners at
  // the projection of the tag-frame corners (+-s/2) to <= 0.5 px. libapriltag's pixel origin
  // is the top-left CORNER of the image, ours the centre of the top-left pixel: subtract 0.5.
  const Studio studio(defaultConfig());
  const double t = 4.0;
  const Scene scene = studio.sceneAt(t, kLayerProp);
  const Pose T_world_prop = studio.T_world_prop(t);
  apriltag_family_t* family = tag36h11_create();
  apriltag_detector_t* detector = apriltag_detector_create();
  apriltag_detector_add_family(detector, family);
  detector->quad_decimate = 1;
  detector->nthreads = 1;
  const int W = 400;
  const double px = 0.0005, c0 = 0.5 * (W - 1);
  const int ss = 4;
  double max_err = 0;
  for (const PropTag& tag : studio.prop().tags) {
    const Pose T_world_tag = T_world_prop * tag.T_prop_tag;
    image_u8_t* image = image_u8_create(W, W);
    for (int v = 0; v < W; ++v)
      for (int u = 0; u < W; ++u) {
        double sum = 0;
        for (int sy = 0; sy < ss; ++sy)
          for (int sx = 0; sx < ss; ++sx) {
            const double x = (u - c0 + (sx + 0.5) / ss - 0.5) * px;
            const double y = (v - c0 + (sy + 0.5) / ss - 0.5) * px;
            Ray ray{T_world_tag * Eigen::Vector3d(x, y, -1.0), T_world_tag.linear().col(2)};
            Hit hit;
            scene.trace(ray, hit);
            sum += hit.rgb.mean();
          }
        const double lin = sum / (ss * ss);
        const double srgb = lin <= 0.0031308 ? 12.92 * lin : 1.055 * std::pow(lin, 1 / 2.4) - 0.055;
        image->buf[v * image->stride + u] = static_cast<uint8_t>(std::lround(std::clamp(srgb, 0.0, 1.0) * 255));
      }
    zarray_t* detections = apriltag_detector_detect(detector, image);
    ASSERT_EQ(zarray_size(detections), 1) << "tag id " << tag.id;
    apriltag_detection_t* det;
    zarray_get(detections, 0, &det);
    EXPECT_EQ(det->id, tag.id);
    const double h = 0.5 * tag.size_m;
    const Eigen::Vector2d corners[4] = {{-h, h}, {h, h}, {h, -h}, {-h, -h}};  // libapriltag p[0..3]
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d expected = corners[k] / px + Eigen::Vector2d(c0, c0);
      const Eigen::Vector2d got(det->p[k][0] - 0.5, det->p[k][1] - 0.5);
      max_err = std::max(max_err, (got - expected).norm());
    }
    apriltag_detections_destroy(detections);
    image_u8_destroy(image);
  }
  apriltag_detector_destroy(detector);
  tag36h11_destroy(family);
  EXPECT_LE(max_err, 0.5);
  std::printf("[ prop tags ] 5/5 decoded, max corner error %.3f px (tag = 240 px)\n", max_err);
}

TEST(Mesh, PlyRoundTripIsExactAndObjHasTheCounts) {
  const Studio studio(defaultConfig());
  const TriangleMesh mesh = studio.actorMesh(2.0);
  const fs::path dir = tmpDir("mesh");
  writePly(mesh, dir / "actor.ply");
  writeObj(mesh, dir / "actor.obj");
  const TriangleMesh back = readPly(dir / "actor.ply");
  ASSERT_EQ(back.vertices.size(), mesh.vertices.size());
  ASSERT_EQ(back.faces.size(), mesh.faces.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    ASSERT_EQ(back.vertices[i], mesh.vertices[i]);
    ASSERT_EQ(back.normals[i], mesh.normals[i]);
  }
  for (size_t i = 0; i < mesh.faces.size(); ++i) ASSERT_EQ(back.faces[i], mesh.faces[i]);

  std::ifstream ply(dir / "actor.ply", std::ios::binary);
  std::string header((std::istreambuf_iterator<char>(ply)), {});
  header = header.substr(0, header.find("end_header"));
  EXPECT_NE(header.find("binary_little_endian"), std::string::npos);
  EXPECT_NE(header.find("metres"), std::string::npos);
  EXPECT_NE(header.find("z up"), std::string::npos);

  std::ifstream obj(dir / "actor.obj");
  std::string line;
  size_t v = 0, vn = 0, f = 0;
  bool face_format_ok = true;
  while (std::getline(obj, line)) {
    if (line.rfind("v ", 0) == 0) ++v;
    if (line.rfind("vn ", 0) == 0) ++vn;
    if (line.rfind("f ", 0) == 0) {
      ++f;
      face_format_ok = face_format_ok && line.find("//") != std::string::npos;
    }
  }
  EXPECT_EQ(v, mesh.vertices.size());
  EXPECT_EQ(vn, mesh.normals.size());
  EXPECT_EQ(f, mesh.faces.size());
  EXPECT_TRUE(face_format_ok);
  for (const auto& p : fs::directory_iterator(dir))
    EXPECT_EQ(p.path().filename().string().find(".tmp"), std::string::npos) << "temporary left behind";
}

TEST(Mesh, ReadPlyRejectsMalformedFilesNamingThem) {
  const fs::path dir = tmpDir("bad_ply");
  TriangleMesh tri;
  tri.vertices = {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(0, 1, 0)};
  tri.normals = {Eigen::Vector3f(0, 0, 1), Eigen::Vector3f(0, 0, 1), Eigen::Vector3f(0, 0, 1)};
  tri.faces = {Eigen::Vector3i(0, 1, 2)};
  writePly(tri, dir / "good.ply");
  std::ifstream in(dir / "good.ply", std::ios::binary);
  const std::string good((std::istreambuf_iterator<char>(in)), {});
  auto expectError = [&](const std::string& name, const std::string& bytes, const std::string& what) {
    const fs::path path = dir / name;
    std::ofstream(path, std::ios::binary) << bytes;
    try {
      readPly(path);
      ADD_FAILURE() << name << ": no error";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().file, path.string()) << name;
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << name << ": " << e.what();
    }
  };
  expectError("truncated.ply", good.substr(0, good.size() - 5), "truncated");
  expectError("magic.ply", "plx" + good.substr(3), "magic");
  std::string ascii = good;
  ascii.replace(ascii.find("binary_little_endian"), 20, "ascii");
  expectError("ascii.ply", ascii, "format");
  std::string bad_index = good;
  bad_index[bad_index.size() - 4] = 9;  // last index (little endian) -> 9, out of range
  expectError("index.ply", bad_index, "out of range");
  EXPECT_THROW(readPly(dir / "missing.ply"), Error);
  EXPECT_EQ(readPly(dir / "good.ply").faces.size(), 1u);
}

TEST(Studio, SceneIsDeterministicAndLayersSelectObjects) {
  const Studio a(defaultConfig()), b(defaultConfig());
  const Eigen::Vector3d eye(2, -4, 1.6);
  int classes[8] = {0};
  const Scene sa = a.sceneAt(3.3, kLayersPlate), sb = b.sceneAt(3.3, kLayersPlate);
  const Scene actor_only = a.sceneAt(3.3, kLayerActor);
  for (int i = 0; i < 400; ++i) {
    const Eigen::Vector3d target(-2 + 4.0 * (i % 20) / 19, -1 + 2.5 * (i / 20) / 19.0, 0.1 + 1.8 * (i / 20) / 19.0);
    const Ray ray{eye, (target - eye).normalized()};
    Hit ha, hb, ho;
    sa.trace(ray, ha);
    sb.trace(ray, hb);
    EXPECT_EQ(ha.t, hb.t);
    EXPECT_EQ(ha.rgb, hb.rgb);
    classes[static_cast<int>(ha.cls)]++;
    const bool hit_only = actor_only.trace(ray, ho);
    EXPECT_EQ(hit_only, ho.cls == ObjectClass::kActor);
    if (ha.cls == ObjectClass::kActor) {
      EXPECT_EQ(ho.t, ha.t);
    }
    if (!hit_only) {
      EXPECT_EQ(ho.rgb, actor_only.environment_rgb);
    }
  }
  EXPECT_GT(classes[static_cast<int>(ObjectClass::kStage)], 100);
  StudioConfig bad = defaultConfig();
  bad.take_duration_s = 0;
  try {
    Studio s(bad);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "take_duration_s");
  }
  StudioConfig none = defaultConfig();
  none.with_actor = false;
  EXPECT_TRUE(Studio(none).actorMesh(1.0).faces.empty());
  EXPECT_TRUE(Studio(none).actorBounds(1.0).isEmpty());
}

}  // namespace
}  // namespace previz::synth
