// Visual hull carving: the contract (options, errors, dropped cameras), the k-of-n point test
// against an independent implementation of the exact hull (hull_fixture.h), conservativeness of
// the cell hierarchy, work that follows the surface, determinism across thread counts, the
// surface mesh, and rigs of any size (100 cameras against a true shape, every camera carving,
// camera order and camera-set width not changing the result). Silhouettes: the studio's true
// actor mesh rasterized through each witness's true lens (1280x720); for rigs of 100 cameras,
// analytic silhouettes of balls.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <random>
#include <set>
#include <tuple>
#include <unordered_set>

#include <opencv2/imgproc.hpp>

#include "carving/hull.h"
#include "core/error.h"
#include "core/pose.h"
#include "hull_fixture.h"

namespace previz::carving {
namespace {

using namespace previz::carving::test;

const StudioFrame& frame() {
  static const StudioFrame f = makeStudioFrame(4.0, 480, 270);
  return f;
}

Silhouettes silhouettes(const StudioFrame& f) {
  Silhouettes s;
  s.masks = f.masks;
  return s;
}

ReferenceHull reference(const StudioFrame& f, const HullOptions& o) {
  ReferenceHull ref;
  ref.cameras = f.witnesses;
  ref.masks = f.masks;
  ref.k = o.k;
  ref.min_views = o.min_views;
  ref.volume = o.volume;
  return ref;
}

std::string errorField(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.context().field.empty() ? e.context().camera : e.context().field;
  }
  return "(no error)";
}

TEST(HullOptions, ValidateNamesTheBadField) {
  HullOptions o;
  EXPECT_NO_THROW(o.validate());
  o.voxel_m = 0;
  EXPECT_EQ(errorField([&] { o.validate(); }), "voxel_m");
  o = HullOptions{};
  o.k = -1;
  EXPECT_EQ(errorField([&] { o.validate(); }), "k");
  o = HullOptions{};
  o.min_views = 0;
  EXPECT_EQ(errorField([&] { o.validate(); }), "min_views");
  o = HullOptions{};
  o.volume = Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 1));
  EXPECT_EQ(errorField([&] { o.validate(); }), "volume");
  o = HullOptions{};
  o.voxel_m = 1e-5;  // 400000 cells along x
  EXPECT_EQ(errorField([&] { o.validate(); }), "voxel_m");
}

TEST(Carver, BadSilhouettesThrowNamingTheCamera) {
  const StudioFrame& f = frame();
  Carver carver(f.witnesses);
  Silhouettes s = silhouettes(f);
  s.masks.pop_back();
  EXPECT_EQ(errorField([&] { carver.carve(s); }), "masks");
  s = silhouettes(f);
  cv::resize(s.masks[3], s.masks[3], cv::Size(640, 360));
  try {
    carver.carve(s);
    FAIL() << "no error for a 640x360 mask of a 1280x720 camera";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, f.witnesses[3].camera.name);
  }
  s = silhouettes(f);
  s.masks[1].convertTo(s.masks[1], CV_32F);
  EXPECT_EQ(errorField([&] { carver.carve(s); }), "masks");
}

TEST(Carver, TooFewCamerasGiveAnEmptyReportedHull) {
  const StudioFrame& f = frame();
  Carver carver(f.witnesses);
  Silhouettes s = silhouettes(f);
  for (size_t c = 1; c < s.masks.size(); ++c) s.masks[c] = cv::Mat();
  const VisualHull hull = carver.carve(s);
  EXPECT_TRUE(hull.empty());
  EXPECT_EQ(hull.stats.cameras_used.size(), 1u);
  EXPECT_EQ(hull.stats.cameras_dropped.size(), f.witnesses.size() - 1);
  EXPECT_FALSE(carver.inside(Eigen::Vector3d(1.3, -0.5, 1.0)));
  const cv::Mat depth = carver.depth(hull, f.main, cv::Mat());
  EXPECT_EQ(cv::countNonZero(depth < 1e30), 0);
}

// Random points around the actor, half of them on its true surface (where the hull boundary is).
std::vector<Eigen::Vector3d> probePoints(const StudioFrame& f, int n) {
  std::mt19937 rng(7);
  Eigen::AlignedBox3d box = f.actor_bounds;
  box.min() -= Eigen::Vector3d::Constant(0.15);
  box.max() += Eigen::Vector3d::Constant(0.15);
  box.min().z() = std::max(box.min().z(), 0.0);
  std::uniform_real_distribution<double> uni(0, 1);
  std::normal_distribution<double> jitter(0, 0.01);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < n; ++i) {
    if (i % 2) {
      const auto& v = f.actor.vertices[rng() % f.actor.vertices.size()];
      pts.push_back(v.cast<double>() + Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng)));
    } else {
      pts.push_back(box.min() + box.sizes().cwiseProduct(Eigen::Vector3d(uni(rng), uni(rng), uni(rng))));
    }
  }
  return pts;
}

TEST(Carver, PointTestMatchesExactHullForEveryK) {
  const StudioFrame& f = frame();
  const std::vector<Eigen::Vector3d> pts = probePoints(f, 20000);
  for (int k : {0, 1, 2}) {
    HullOptions o;
    o.k = k;
    Carver carver(f.witnesses, o);
    const VisualHull hull = carver.carve(silhouettes(f));
    const ReferenceHull ref = reference(f, o);
    int mismatches = 0, inside = 0;
    for (const auto& p : pts) {
      const bool expected = ref.inside(p);
      inside += expected;
      mismatches += carver.inside(hull, p) != expected;
    }
    std::printf("k = %d: %d of %zu probe points inside, %d disagree with the reference\n", k,
                inside, pts.size(), mismatches);
    EXPECT_GT(inside, 2000);
    EXPECT_LE(mismatches, 2);  // only points within ~1e-9 px of a pixel edge may differ
  }
}

// Which kept cell (if any) holds a finest voxel.
struct CellIndex {
  std::vector<std::set<std::tuple<int, int, int>>> inside_by_level;
  std::set<std::tuple<int, int, int>> surface;
  explicit CellIndex(const VisualHull& hull) : inside_by_level(hull.levels) {
    for (const auto& c : hull.inside) inside_by_level[c.level].emplace(c.index.x(), c.index.y(), c.index.z());
    for (const auto& c : hull.surface) surface.emplace(c.index.x(), c.index.y(), c.index.z());
  }
  // 0 = in no kept cell, 1 = in an inside cell, 2 = in a surface cell.
  int kind(const VisualHull& hull, const Eigen::Vector3d& p) const {
    const Eigen::Vector3d g = (p - hull.origin) / hull.voxel_m;
    const int x = static_cast<int>(std::floor(g.x())), y = static_cast<int>(std::floor(g.y())),
              z = static_cast<int>(std::floor(g.z()));
    if (surface.count({x, y, z})) return 2;
    for (int l = 0; l < hull.levels; ++l)
      if (inside_by_level[l].count({x >> l, y >> l, z >> l})) return 1;
    return 0;
  }
};

// Every point of the exact hull lies in a kept cell, and every point of an inside cell is in
// the exact hull: culling and "wholly inside" never lie.
void expectConservative(const StudioFrame& f, const std::vector<int>& ks) {
  for (int k : ks) {
    HullOptions o;
    o.k = k;
    Carver carver(f.witnesses, o);
    const VisualHull hull = carver.carve(silhouettes(f));
    const ReferenceHull ref = reference(f, o);
    const CellIndex index(hull);
    int hull_points = 0, lost = 0, in_inside_cells = 0, wrong_inside = 0;
    for (const auto& p : probePoints(f, 40000)) {
      const int kind = index.kind(hull, p);
      if (ref.inside(p)) {
        ++hull_points;
        lost += kind == 0;
      }
      if (kind == 1) {
        ++in_inside_cells;
        wrong_inside += !ref.inside(p);
      }
    }
    std::printf("k = %d: %d hull points, %d outside every kept cell; %d points in inside cells, "
                "%d of them outside the hull\n",
                k, hull_points, lost, in_inside_cells, wrong_inside);
    EXPECT_GT(hull_points, 5000);
    EXPECT_EQ(lost, 0);
    EXPECT_GT(in_inside_cells, 2000);
    EXPECT_EQ(wrong_inside, 0);
  }
}

TEST(Carver, CellsAreConservative) { expectConservative(frame(), {0, 1}); }

TEST(Carver, CellsAreConservativeThroughStrongDistortion) {
  // Barrel distortion far beyond the studio's lenses (the image corner moves ~90 px), so that
  // footprints curve: the padding of cell footprints must still contain them.
  Distortion strong;
  strong.k1 = -0.30;
  strong.k2 = 0.10;
  strong.p1 = 0.002;
  strong.p2 = -0.002;
  const StudioFrame f = makeStudioFrame(4.0, 480, 270, false, &strong);
  expectConservative(f, {0});
}

TEST(Carver, WorkFollowsTheSurface) {
  // Halving the cell size multiplies a surface's cell count by ~4 and a volume's by 8.
  const StudioFrame& f = frame();
  long long tested[2], surface[2];
  const double voxels[2] = {0.01, 0.005};
  for (int i = 0; i < 2; ++i) {
    HullOptions o;
    o.voxel_m = voxels[i];
    Carver carver(f.witnesses, o);
    const VisualHull hull = carver.carve(silhouettes(f));
    tested[i] = 0;
    for (long long t : hull.stats.cells_tested) tested[i] += t;
    surface[i] = hull.stats.surface_cells;
    std::printf("voxel %.3f m: %lld cells tested over %d levels, %lld surface, %lld inside\n",
                voxels[i], tested[i], hull.levels, surface[i], hull.stats.inside_cells);
  }
  const double ratio = double(tested[1]) / tested[0];
  std::printf("tested-cell ratio 5 mm / 1 cm: %.2f (surface ~4, volume 8)\n", ratio);
  EXPECT_GT(ratio, 3.0);
  EXPECT_LT(ratio, 5.0);
  // A dense grid at 5 mm would test 800 x 800 x 500 = 3.2e8 cells.
  EXPECT_LT(tested[1], 3.2e8 / 300);
}

TEST(Carver, ResultsDoNotDependOnThreadCount) {
  const StudioFrame& f = frame();
  HullOptions o;
  o.threads = 1;
  Carver one(f.witnesses, o);
  o.threads = 2;
  Carver two(f.witnesses, o);
  const VisualHull a = one.carve(silhouettes(f)), b = two.carve(silhouettes(f));
  ASSERT_EQ(a.surface.size(), b.surface.size());
  ASSERT_EQ(a.inside.size(), b.inside.size());
  for (size_t i = 0; i < a.surface.size(); ++i) {
    ASSERT_EQ(a.surface[i].index, b.surface[i].index) << i;
  }
  for (size_t i = 0; i < a.inside.size(); ++i) {
    ASSERT_EQ(a.inside[i].index, b.inside[i].index) << i;
    ASSERT_EQ(a.inside[i].level, b.inside[i].level) << i;
  }
  const cv::Mat da = one.depth(a, f.main, f.main_raster.mask);
  const cv::Mat db = two.depth(b, f.main, f.main_raster.mask);
  EXPECT_EQ(cv::norm(da != db, cv::NORM_L1), 0);
  const TriangleMesh ma = one.mesh(a), mb = two.mesh(b);
  ASSERT_EQ(ma.vertices.size(), mb.vertices.size());
  ASSERT_EQ(ma.faces.size(), mb.faces.size());
  for (size_t i = 0; i < ma.vertices.size(); ++i) ASSERT_EQ(ma.vertices[i], mb.vertices[i]) << i;
}

TEST(HullMesh, HugsTheExactHullWithOutwardNormalsAndNoHoles) {
  const StudioFrame& f = frame();
  HullOptions o;
  Carver carver(f.witnesses, o);
  const VisualHull hull = carver.carve(silhouettes(f));
  const TriangleMesh mesh = carver.mesh(hull);
  ASSERT_GT(mesh.vertices.size(), 10000u);
  ASSERT_EQ(mesh.normals.size(), mesh.vertices.size());
  const ReferenceHull ref = reference(f, o);
  const double v = o.voxel_m;

  // Distance of each (sampled) vertex to the exact hull's boundary, searched along its normal
  // in steps of a tenth of a voxel; and whether the normal points from inside to outside.
  int sampled = 0, within_voxel = 0, outward = 0;
  for (size_t i = 0; i < mesh.vertices.size(); i += 7) {
    const Eigen::Vector3d p = mesh.vertices[i].cast<double>();
    const Eigen::Vector3d n = mesh.normals[i].cast<double>();
    ++sampled;
    const bool at = ref.inside(p);
    for (int s = 1; s <= 30; ++s) {
      const double d = 0.1 * v * s;
      if (ref.inside(p + d * n) != at || ref.inside(p - d * n) != at) {
        within_voxel += d <= v;
        break;
      }
    }
    outward += ref.inside(p - 1.5 * v * n) && !ref.inside(p + 1.5 * v * n);
  }
  // Watertightness: every edge shared by exactly two faces.
  std::map<std::pair<int, int>, int> edges;
  for (const auto& face : mesh.faces)
    for (int e = 0; e < 3; ++e) {
      const int a = face[e], b = face[(e + 1) % 3];
      ++edges[{std::min(a, b), std::max(a, b)}];
    }
  int boundary = 0, non_manifold = 0;
  for (const auto& [e, count] : edges) {
    boundary += count == 1;
    non_manifold += count > 2;
  }
  const long long euler = static_cast<long long>(mesh.vertices.size()) -
                          static_cast<long long>(edges.size()) +
                          static_cast<long long>(mesh.faces.size());
  std::printf("mesh: %zu vertices, %zu faces; %d sampled: %.2f %% within one voxel of the exact "
              "hull, %.2f %% outward normals; edges %zu, boundary %d, non-manifold %d, Euler "
              "characteristic %lld\n",
              mesh.vertices.size(), mesh.faces.size(), sampled, 100.0 * within_voxel / sampled,
              100.0 * outward / sampled, edges.size(), boundary, non_manifold, euler);
  EXPECT_GE(double(within_voxel) / sampled, 0.95);
  EXPECT_GE(double(outward) / sampled, 0.95);
  EXPECT_LE(boundary, static_cast<int>(edges.size() / 1000));
}

// ---------------------------------------------------------------------------------------------
// Rigs of any size: 100 cameras around balls with analytic silhouettes
// ---------------------------------------------------------------------------------------------
struct Ball {
  Eigen::Vector3d centre;
  double radius;
};

// n ideal cameras w x h (fx = fy = f_px, principal point at the centre) on a sphere of radius
// distance_m around target, looking at it, their directions spread evenly by the Fibonacci
// lattice (Gonzalez 2010).
std::vector<RigCamera> sphereRig(int n, const Eigen::Vector3d& target, double distance_m, int w,
                                 int h, double f_px) {
  std::vector<RigCamera> rig(n);
  const double golden_angle = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n, r = std::sqrt(1.0 - z * z);
    const Eigen::Vector3d dir(r * std::cos(golden_angle * i), r * std::sin(golden_angle * i), z);
    Camera& cam = rig[i].camera;
    cam.name = "sphere" + std::to_string(i);
    cam.width = w;
    cam.height = h;
    cam.fx = cam.fy = f_px;
    cam.cx = 0.5 * (w - 1);
    cam.cy = 0.5 * (h - 1);
    rig[i].T_world_cam = lookAt(target + distance_m * dir, target);
  }
  return rig;
}

// Silhouette of a union of balls as a conservative keyer would give it: a pixel is inside when
// any ray through its square meets a ball. The rays through a pixel's square lie within
// sqrt(2) / 2 / f rad of its centre's ray (an ideal pinhole spreads rays by at most 1 / f rad
// per pixel, at the principal point), so every point of a ball falls in an inside pixel and the
// hull contains the balls.
cv::Mat ballSilhouette(const RigCamera& rc, const std::vector<Ball>& balls) {
  const Camera& cam = rc.camera;
  const double margin = std::sqrt(0.5) / cam.fx;
  cv::Mat mask = cv::Mat::zeros(cam.height, cam.width, CV_8UC1);
  for (const Ball& b : balls) {
    const Eigen::Vector3d to_centre = rc.T_world_cam.inverse() * b.centre;
    const double reach = std::asin(std::min(1.0, b.radius / to_centre.norm())) + margin;
    for (int v = 0; v < cam.height; ++v)
      for (int u = 0; u < cam.width; ++u) {
        const Eigen::Vector3d ray((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
        if (std::atan2(ray.cross(to_centre).norm(), ray.dot(to_centre)) <= reach)
          mask.at<std::uint8_t>(v, u) = 255;
      }
  }
  return mask;
}

Silhouettes ballSilhouettes(const std::vector<RigCamera>& rig, const std::vector<Ball>& balls) {
  Silhouettes s;
  s.masks.resize(rig.size());
  parallelFor(static_cast<int>(rig.size()),
              [&](int c) { s.masks[c] = ballSilhouette(rig[c], balls); });
  return s;
}

HullOptions ballOptions(const Ball& b) {
  HullOptions o;
  o.voxel_m = 0.01;
  o.volume = Eigen::AlignedBox3d(b.centre - Eigen::Vector3d::Constant(0.7),
                                 b.centre + Eigen::Vector3d::Constant(0.7));
  return o;
}

// The carved hull's volume: inside cells whole, surface voxels by the exact point test at the
// centres of their 8 octants.
double hullVolume(const Carver& carver, const VisualHull& hull) {
  const double v = hull.voxel_m;
  double volume = 0;
  for (const HullCell& c : hull.inside) volume += std::pow(v * (1 << c.level), 3);
  for (const HullCell& c : hull.surface) {
    int in = 0;
    for (int o = 0; o < 8; ++o) {
      const Eigen::Vector3d p =
          hull.origin + v * (c.index.cast<double>() +
                             Eigen::Vector3d(0.25 + 0.5 * (o & 1), 0.25 + 0.5 * ((o >> 1) & 1),
                                             0.25 + 0.5 * (o >> 2)));
      in += carver.inside(hull, p);
    }
    volume += v * v * v * in / 8.0;
  }
  return volume;
}

// Points of the ball: n on its surface (Fibonacci lattice) and n uniform inside.
std::vector<Eigen::Vector3d> ballPoints(const Ball& b, int n) {
  std::vector<Eigen::Vector3d> pts;
  const double golden_angle = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - (2.0 * i + 1.0) / n, r = std::sqrt(1.0 - z * z);
    pts.push_back(b.centre + b.radius * Eigen::Vector3d(r * std::cos(golden_angle * i),
                                                        r * std::sin(golden_angle * i), z));
  }
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(-1, 1);
  while (static_cast<int>(pts.size()) < 2 * n) {
    const Eigen::Vector3d d(uni(rng), uni(rng), uni(rng));
    if (d.squaredNorm() <= 1) pts.push_back(b.centre + b.radius * d);
  }
  return pts;
}

TEST(Carver, HundredCamerasHoldTheBallAndTightenItsVolume) {
  // A 0.4 m ball seen from 2 m by 320x240 cameras (the ball ~120 px across). With conservative
  // silhouettes the hull contains the ball; its excess volume comes from the cones' facets and
  // from the silhouettes' margin and pixel steps, all shrinking as more cameras bound each
  // direction. Measured (carving_tests --gtest_filter='Carver.Hundred*'): 12 cameras +4.4 %,
  // 100 cameras +1.8 %.
  const Ball ball{Eigen::Vector3d(0.1, -0.2, 1.2), 0.4};
  const double true_volume = 4.0 / 3.0 * M_PI * std::pow(ball.radius, 3);
  const std::vector<Eigen::Vector3d> pts = ballPoints(ball, 2000);
  const HullOptions o = ballOptions(ball);
  double excess[2];
  const int n_cameras[2] = {12, 100};
  for (int i = 0; i < 2; ++i) {
    const std::vector<RigCamera> rig = sphereRig(n_cameras[i], ball.centre, 2.0, 320, 240, 300);
    Carver carver(rig, o);
    const VisualHull hull = carver.carve(ballSilhouettes(rig, {ball}));
    ASSERT_EQ(hull.stats.cameras_used.size(), rig.size());
    const CellIndex index(hull);
    int lost = 0, lost_by_cells = 0;
    for (const auto& p : pts) {
      lost += !carver.inside(hull, p);
      lost_by_cells += index.kind(hull, p) == 0;
    }
    const double volume = hullVolume(carver, hull);
    excess[i] = volume / true_volume - 1;
    std::printf("%d cameras: %zu ball points, %d outside the hull, %d outside every kept cell; "
                "hull %.5f m^3, ball %.5f m^3: %+.2f %%; %lld surface, %lld inside cells, "
                "%.1f ms\n",
                n_cameras[i], pts.size(), lost, lost_by_cells, volume, true_volume,
                100 * excess[i], hull.stats.surface_cells, hull.stats.inside_cells,
                hull.stats.ms);
    EXPECT_EQ(lost, 0);
    EXPECT_EQ(lost_by_cells, 0);
    EXPECT_GT(excess[i], 0.0);
  }
  EXPECT_LT(excess[0], 0.08);
  EXPECT_LT(excess[1], 0.03);
  EXPECT_LT(excess[1], 0.5 * excess[0]);
}

TEST(Carver, CameraOrderDoesNotChangeTheHull) {
  const Ball ball{Eigen::Vector3d(0.1, -0.2, 1.2), 0.4};
  const std::vector<RigCamera> rig = sphereRig(100, ball.centre, 2.0, 160, 120, 150);
  const Silhouettes s = ballSilhouettes(rig, {ball});
  std::vector<int> order(rig.size());
  for (size_t c = 0; c < order.size(); ++c) order[c] = static_cast<int>(c);
  std::shuffle(order.begin(), order.end(), std::mt19937(3));
  std::vector<RigCamera> shuffled_rig;
  Silhouettes shuffled;
  for (int c : order) {
    shuffled_rig.push_back(rig[c]);
    shuffled.masks.push_back(s.masks[c]);
  }
  Carver a(rig, ballOptions(ball)), b(shuffled_rig, ballOptions(ball));
  const VisualHull ha = a.carve(s), hb = b.carve(shuffled);
  ASSERT_GT(ha.surface.size(), 1000u);
  ASSERT_EQ(ha.surface.size(), hb.surface.size());
  ASSERT_EQ(ha.inside.size(), hb.inside.size());
  for (size_t i = 0; i < ha.surface.size(); ++i)
    ASSERT_EQ(ha.surface[i].index, hb.surface[i].index) << i;
  for (size_t i = 0; i < ha.inside.size(); ++i) {
    ASSERT_EQ(ha.inside[i].index, hb.inside[i].index) << i;
    ASSERT_EQ(ha.inside[i].level, hb.inside[i].level) << i;
  }
  // A view between the witnesses: the same depth to the bit.
  RigCamera view;
  view.camera = rig[0].camera;
  view.T_world_cam = lookAt(ball.centre + Eigen::Vector3d(1.1, 1.3, 0.9), ball.centre);
  const cv::Mat da = a.depth(ha, view, cv::Mat()), db = b.depth(hb, view, cv::Mat());
  EXPECT_GT(cv::countNonZero(da < 1e30), 1000);
  EXPECT_EQ(cv::norm(da != db, cv::NORM_L1), 0);
}

TEST(Carver, TwoWordCameraSetsGiveTheEightCameraHullToTheBit) {
  // The studio's 8 witnesses at indices 64..71 of a 72-camera rig whose first 64 cameras have
  // no silhouette: camera sets of two words (the path of rigs over 64 cameras) must give the
  // hull, depth and mesh of the 8 alone (one word) to the bit.
  const StudioFrame& f = frame();
  std::vector<RigCamera> rig;
  Silhouettes s;
  for (int c = 0; c < 64; ++c) {
    rig.push_back(f.witnesses[c % f.witnesses.size()]);
    rig.back().camera.name = "absent" + std::to_string(c);
    s.masks.emplace_back();
  }
  rig.insert(rig.end(), f.witnesses.begin(), f.witnesses.end());
  s.masks.insert(s.masks.end(), f.masks.begin(), f.masks.end());
  Carver eight(f.witnesses), many(rig);
  const VisualHull a = eight.carve(silhouettes(f)), b = many.carve(s);
  ASSERT_EQ(b.stats.cameras_used.size(), f.witnesses.size());
  ASSERT_EQ(a.surface.size(), b.surface.size());
  ASSERT_EQ(a.inside.size(), b.inside.size());
  for (size_t i = 0; i < a.surface.size(); ++i)
    ASSERT_EQ(a.surface[i].index, b.surface[i].index) << i;
  for (size_t i = 0; i < a.inside.size(); ++i) {
    ASSERT_EQ(a.inside[i].index, b.inside[i].index) << i;
    ASSERT_EQ(a.inside[i].level, b.inside[i].level) << i;
  }
  const cv::Mat da = eight.depth(a, f.main, f.main_raster.mask);
  const cv::Mat db = many.depth(b, f.main, f.main_raster.mask);
  EXPECT_EQ(cv::norm(da != db, cv::NORM_L1), 0);
  const TriangleMesh ma = eight.mesh(a), mb = many.mesh(b);
  ASSERT_EQ(ma.vertices.size(), mb.vertices.size());
  ASSERT_EQ(ma.faces.size(), mb.faces.size());
  for (size_t i = 0; i < ma.vertices.size(); ++i) ASSERT_EQ(ma.vertices[i], mb.vertices[i]) << i;
}

TEST(Carver, EveryCameraOfALargeRigCarves) {
  // A small ball beside the big one that only camera x does not see (its silhouette holds the
  // big ball only): camera x alone carves it, whichever word of the camera sets x falls in.
  const Ball ball{Eigen::Vector3d(0.1, -0.2, 1.2), 0.4};
  const std::vector<RigCamera> rig = sphereRig(100, ball.centre, 2.0, 160, 120, 150);
  const HullOptions o = ballOptions(ball);
  Carver carver(rig, o);
  for (int x : {5, 40, 70, 99}) {
    // Beside the big ball as camera x sees it: off its axis by 0.52 m (the big ball's image
    // reaches 0.41 m there), within the volume.
    const Eigen::Vector3d side = rig[x].T_world_cam.linear().col(0);
    const Ball bump{ball.centre + 0.52 * side, 0.06};
    Silhouettes s = ballSilhouettes(rig, {ball, bump});
    s.masks[x] = ballSilhouette(rig[x], {ball});
    Silhouettes without = s;
    without.dropped.assign(rig.size(), "");
    without.dropped[x] = "left out by the test";
    const VisualHull with_x = carver.carve(s), without_x = carver.carve(without);
    const int kind_with = CellIndex(with_x).kind(with_x, bump.centre);
    const int kind_without = CellIndex(without_x).kind(without_x, bump.centre);
    std::printf("camera %d: bump centre in a kept cell without it: %s, with it: %s\n", x,
                kind_without ? "yes" : "no", kind_with ? "yes" : "no");
    EXPECT_TRUE(carver.inside(without_x, bump.centre)) << x;
    EXPECT_NE(kind_without, 0) << x;
    EXPECT_FALSE(carver.inside(with_x, bump.centre)) << x;
    EXPECT_EQ(kind_with, 0) << x;
    // Elsewhere camera x agrees with the others: the big ball stays.
    EXPECT_TRUE(carver.inside(with_x, ball.centre)) << x;
  }
}

}  // namespace
}  // namespace previz::carving
