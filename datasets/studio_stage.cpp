// The green cyclorama, the dark studio around it, and the CG virtual set.
//
// Cyclorama geometry: a floor (z = 0) and two walls (y = +cyc/2 and x = -cyc/2) joined by
// rounded coves of radius kCoveRadius. That surface is the boundary of the convex region
// R = {p : dist(p, O) <= Rc}, O the orthant {x >= -h + Rc, y <= h - Rc, z >= Rc}; a camera
// inside R sees the point where its ray leaves R, which is unique, so the first piece
// (plane, cylinder or sphere) whose candidate point lies on R's boundary is the hit. The
// cyclorama is cut at |x|, |y| <= h and z <= wall height; beyond lies the dark studio (a box
// 30 x 30 x 9 m whose floor continues the stage floor).
#include <algorithm>
#include <cmath>

#include "datasets/detail/studio_detail.h"
#include "datasets/random.h"

namespace previz::synth::detail {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kCoveRadius = 0.6;
constexpr double kStudioHalf = 15.0, kStudioHeight = 9.0;
constexpr double kEps = 1e-9;

const Eigen::Vector3f kScreenGreen(0.08f, 0.45f, 0.12f);
// Chroma-key blue paint, as saturated as the green (its q = (B - max(R, G)) / B is 0.76 where the
// green's is 0.73) and darker, as blue screens are.
const Eigen::Vector3f kScreenBlue(0.05f, 0.11f, 0.46f);

enum StagePiece : int { kFloor = 0, kBackWall = 1, kLeftWall = 2, kCove = 3 };
enum StudioPiece : int { kStudioFloor = 0, kStudioWalls = 1 };

double areaOfLens(double R, double r, double d) {
  // Area of the intersection of two discs (radii R, r, centres d apart).
  if (d >= R + r) return 0;
  if (d <= std::abs(R - r)) return kPi * std::min(R, r) * std::min(R, r);
  const double a = std::clamp((d * d + r * r - R * R) / (2 * d * r), -1.0, 1.0);
  const double b = std::clamp((d * d + R * R - r * r) / (2 * d * R), -1.0, 1.0);
  const double k = (-d + r + R) * (d + r - R) * (d - r + R) * (d + r + R);
  return r * r * std::acos(a) + R * R * std::acos(b) - 0.5 * std::sqrt(std::max(0.0, k));
}

// Slow variation of the screen (uneven paint and lighting): a few 3-D sinusoids with
// seed-dependent directions and phases, smooth across the coves.
struct LowFrequency {
  Eigen::Vector3d k[4];
  double phase[4];
  double amplitude[4];
  explicit LowFrequency(std::uint64_t seed) {
    Rng rng(seed, 0x5CA1AB1E);
    for (int i = 0; i < 4; ++i) {
      Eigen::Vector3d dir(rng.normal(), rng.normal(), rng.normal());
      dir.normalize();
      const double wavelength = rng.uniform(2.5, 7.0);
      k[i] = dir * (2 * kPi / wavelength);
      phase[i] = rng.uniform(0, 2 * kPi);
      amplitude[i] = rng.uniform(0.02, 0.035);
    }
  }
  double operator()(const Eigen::Vector3d& p) const {
    double v = 0;
    for (int i = 0; i < 4; ++i) v += amplitude[i] * smoothWave(k[i].dot(p) + phase[i]);
    return v;
  }
  // A C1 periodic wave (period 2 pi, range [-1, 1]) of alternating parabolas: looks like a
  // sine at a fraction of std::sin's cost, which matters at ~20 M floor pixels per frame.
  static double smoothWave(double x) {
    const double y = x * (1.0 / kPi);
    const double f = y - std::floor(y);             // [0, 1) within a half period
    const double sign = (static_cast<long long>(std::floor(y)) & 1) ? -1.0 : 1.0;
    return sign * 4.0 * f * (1.0 - f);
  }
};

class StagePrimitive final : public Primitive {
 public:
  StagePrimitive(const StudioConfig& config, ShadowCasters casters)
      : backdrop_(config.backdrop), half_(0.5 * config.cyc_size_m),
        wall_height_(config.wall_height_m),
        seed_(static_cast<std::uint32_t>(hashKey(config.seed, 0x57A6E))),
        low_(config.seed),
        casters_(std::move(casters)) {
    // bound_radius stays +inf: the stage surrounds every camera.
  }

  bool intersect(const Ray& ray, double t_min, Hit& hit) const override {
    double t;
    int piece;
    Eigen::Vector3d n;
    if (exitCyclorama(ray, t, piece, n)) {
      const Eigen::Vector3d q = ray.origin + t * ray.dir;
      const bool inside_square = q.x() <= half_ + kEps && q.y() >= -half_ - kEps;
      if (piece == kFloor) {
        if (t <= t_min || t >= hit.t) return false;
        hit.t = t;
        hit.cls = inside_square ? ObjectClass::kStage : ObjectClass::kStudio;
        hit.object = inside_square ? static_cast<int>(kFloor) : static_cast<int>(kStudioFloor);
        hit.normal = n;
        return true;
      }
      if (inside_square && q.z() <= wall_height_ + kEps) {
        if (t <= t_min || t >= hit.t) return false;
        hit.t = t;
        hit.cls = ObjectClass::kStage;
        hit.object = piece;
        hit.normal = n;
        return true;
      }
    }
    // Past the cyclorama's edges or over its walls: the studio box.
    return exitStudio(ray, t_min, hit);
  }

  void shade(const Ray& ray, Hit& hit) const override {
    const Eigen::Vector3d p = ray.origin + hit.t * ray.dir;
    if (hit.cls == ObjectClass::kStudio) {
      // Dark, neutral, slightly uneven: black drapes and a concrete floor.
      const double v = 1.0 + 0.25 * valueNoise(p.x() + p.z(), p.y() + 0.5 * p.z(), 1.3, seed_ ^ 0x1u);
      const Eigen::Vector3f base = hit.object == kStudioFloor ? Eigen::Vector3f(0.05f, 0.048f, 0.045f)
                                                              : Eigen::Vector3f(0.03f, 0.03f, 0.032f);
      hit.rgb = base * static_cast<float>(v);
      return;
    }
    const Eigen::Vector3d& n = hit.normal;
    // Fine texture (fabric / paint) in the plane's own coordinates.
    double u, v;
    if (std::abs(n.z()) >= std::abs(n.x()) && std::abs(n.z()) >= std::abs(n.y())) {
      u = p.x(); v = p.y();
    } else if (std::abs(n.y()) >= std::abs(n.x())) {
      u = p.x(); v = p.z();
    } else {
      u = p.y(); v = p.z();
    }
    const double fine = valueNoise(u, v, 0.008, seed_);
    const double variation = 1.0 + low_(p) + 0.025 * fine;
    // Fill from the cyc lights, a little dimmer towards the far corners.
    const double rho = std::sqrt(p.x() * p.x() + p.y() * p.y());
    const double fill = kFillLight * (1.0 - 0.2 * std::min(1.0, rho / half_));
    const double key = kKeyLightGain * keyLight(p, n) * keyVisibility(casters_, p);
    hit.rgb = (albedo(p, hit.object, u, v) * static_cast<float>((fill + key) * variation)).cwiseMin(1.0f);
  }

 private:
  // The surface's own colour. The set: a wall of painted panels 0.6 m wide in four muted
  // colours with a darker seam between them, and a teal painted concrete floor in slabs;
  // texture at every scale (a difference keyer must not rely on a uniform background). The coves
  // take the wall's panels. The floor's hue is none of the actor's or the crate's: where an
  // object is the floor darkened with the floor's hue, no per-pixel test tells it from a shadow
  // (measured with an oak floor: skin in shade; with a grey one: the grey crate and backpack).
  Eigen::Vector3f albedo(const Eigen::Vector3d& p, int piece, double u, double v) const {
    if (backdrop_ == Backdrop::kGreen) return kScreenGreen;
    if (backdrop_ == Backdrop::kBlue) return kScreenBlue;
    if (piece == kFloor) {
      // Teal painted concrete in 1 m slabs: per-slab tone, trowel marks, dark joints.
      const double sx = std::floor(p.x()), sy = std::floor(p.y());
      const double tone = valueNoise(sx * 7.3 + sy * 3.1, 0.0, 1.0, seed_ ^ 0x0A4u);
      const double marks = valueNoise(p.x(), p.y(), 0.03, seed_ ^ 0x6A1u);
      const bool joint = std::abs(p.x() - sx - 0.5) > 0.494 || std::abs(p.y() - sy - 0.5) > 0.494;
      const float k = static_cast<float>((joint ? 0.5 : 1.0) * (0.9 + 0.08 * tone + 0.05 * marks));
      return Eigen::Vector3f(0.10f, 0.24f, 0.26f) * k;
    }
    static const Eigen::Vector3f kPanels[4] = {{0.42f, 0.36f, 0.28f}, {0.22f, 0.30f, 0.34f},
                                               {0.36f, 0.22f, 0.20f}, {0.30f, 0.32f, 0.24f}};
    const double panel = std::floor(u / 0.6);
    const int index = static_cast<int>(static_cast<long long>(std::abs(panel * 3 + std::floor(v / 1.5))) % 4);
    const double seam = std::abs(u / 0.6 - panel - 0.5) > 0.47 ? 0.5 : 1.0;
    const double brush = valueNoise(u * 3.0, v * 0.4, 0.05, seed_ ^ 0x9B3u);
    return kPanels[index] * static_cast<float>(seam * (0.92 + 0.1 * brush));
  }

  // Where the ray leaves R (see the file comment); false if it never does.
  bool exitCyclorama(const Ray& ray, double& t, int& piece, Eigen::Vector3d& n) const {
    const Eigen::Vector3d& o = ray.origin;
    const Eigen::Vector3d& d = ray.dir;
    const double xm = -half_ + kCoveRadius;  // orthant O: x >= xm, y <= ym, z >= zm
    const double ym = half_ - kCoveRadius;
    const double zm = kCoveRadius;
    const double tol = 1e-7;
    // Floor (most rays end here).
    if (d.z() < 0) {
      t = -o.z() / d.z();
      const Eigen::Vector3d q = o + t * d;
      if (q.x() >= xm - tol && q.y() <= ym + tol) {
        piece = kFloor;
        n = Eigen::Vector3d::UnitZ();
        return true;
      }
    }
    if (d.y() > 0) {
      t = (half_ - o.y()) / d.y();
      const Eigen::Vector3d q = o + t * d;
      if (q.x() >= xm - tol && q.z() >= zm - tol) {
        piece = kBackWall;
        n = -Eigen::Vector3d::UnitY();
        return true;
      }
    }
    if (d.x() < 0) {
      t = (-half_ - o.x()) / d.x();
      const Eigen::Vector3d q = o + t * d;
      if (q.y() <= ym + tol && q.z() >= zm - tol) {
        piece = kLeftWall;
        n = Eigen::Vector3d::UnitX();
        return true;
      }
    }
    // Coves: far roots of the three edge cylinders, then the corner sphere.
    auto cylinder = [&](int axis, const Eigen::Vector3d& c) {
      // Cylinder of radius Rc around the line through c along 'axis'.
      Eigen::Vector3d oc = o - c, dd = d;
      oc[axis] = 0;
      dd[axis] = 0;
      const double a = dd.squaredNorm();
      if (a < 1e-14) return -1.0;
      const double b = oc.dot(dd), cc = oc.squaredNorm() - kCoveRadius * kCoveRadius;
      const double h = b * b - a * cc;
      if (h < 0) return -1.0;
      return (-b + std::sqrt(h)) / a;
    };
    auto onCove = [&](const Eigen::Vector3d& q) {
      // On R's boundary: distance to the orthant equals Rc.
      const Eigen::Vector3d c(std::max(q.x(), xm), std::min(q.y(), ym), std::max(q.z(), zm));
      return std::abs((q - c).norm() - kCoveRadius) < 1e-6;
    };
    auto accept = [&](double tc, const Eigen::Vector3d& axis_point, int axis) {
      if (!(tc > 0)) return false;
      const Eigen::Vector3d q = o + tc * d;
      if (!onCove(q)) return false;
      Eigen::Vector3d c = axis_point;
      if (axis >= 0) c[axis] = q[axis];
      t = tc;
      piece = kCove;
      n = (c - q).normalized();  // towards the axis: the inside of R
      return true;
    };
    const Eigen::Vector3d c_back(0, ym, zm), c_left(xm, 0, zm), c_vert(xm, ym, 0);
    if (accept(cylinder(0, c_back), c_back, 0)) return true;
    if (accept(cylinder(1, c_left), c_left, 1)) return true;
    if (accept(cylinder(2, c_vert), c_vert, 2)) return true;
    {
      const Eigen::Vector3d corner(xm, ym, zm);
      const Eigen::Vector3d oc = o - corner;
      const double b = oc.dot(d), c = oc.squaredNorm() - kCoveRadius * kCoveRadius;
      const double h = b * b - c;
      if (h >= 0 && accept(-b + std::sqrt(h), corner, -1)) return true;
    }
    return false;
  }

  bool exitStudio(const Ray& ray, double t_min, Hit& hit) const {
    const Eigen::Vector3d lo(-kStudioHalf, -kStudioHalf, 0), hi(kStudioHalf, kStudioHalf, kStudioHeight);
    double t_exit = std::numeric_limits<double>::infinity();
    int axis_exit = -1;
    for (int a = 0; a < 3; ++a) {
      const double d = ray.dir[a];
      if (d == 0) continue;
      const double ta = ((d > 0 ? hi[a] : lo[a]) - ray.origin[a]) / d;
      if (ta < t_exit) {
        t_exit = ta;
        axis_exit = a;
      }
    }
    if (axis_exit < 0 || t_exit <= t_min || t_exit >= hit.t) return false;
    hit.t = t_exit;
    hit.cls = ObjectClass::kStudio;
    const bool floor = axis_exit == 2 && ray.dir.z() < 0;
    hit.object = floor ? kStudioFloor : kStudioWalls;
    hit.normal = Eigen::Vector3d::Zero();
    hit.normal[axis_exit] = ray.dir[axis_exit] > 0 ? -1 : 1;
    return true;
  }

  Backdrop backdrop_;
  double half_, wall_height_;
  std::uint32_t seed_;
  LowFrequency low_;
  ShadowCasters casters_;
};

// ---- CG virtual set --------------------------------------------------------------------------

enum CgMaterial : int { kStone, kWood, kDarkWood, kBrick, kTiles };

Eigen::Vector3f cgAlbedo(int material, const Eigen::Vector3d& p) {
  switch (material) {
    case kStone: {
      // Pale stone with darker horizontal joints every 0.5 m.
      const double joint = std::abs(std::remainder(p.z(), 0.5));
      const float base = static_cast<float>(1.0 + 0.08 * valueNoise(p.x() + p.y(), p.z(), 0.15, 77u));
      if (joint < 0.012) return Eigen::Vector3f(0.30f, 0.26f, 0.22f);
      return Eigen::Vector3f(0.62f, 0.55f, 0.45f) * base;
    }
    case kWood: {
      const double grain = 0.5 + 0.5 * std::sin(p.y() * 90 + 6 * valueNoise(p.x(), p.y(), 0.2, 31u));
      return Eigen::Vector3f(0.42f, 0.21f, 0.08f) * static_cast<float>(0.85 + 0.15 * grain);
    }
    case kDarkWood: return Eigen::Vector3f(0.12f, 0.08f, 0.06f);
    case kBrick: {
      // Running bond, 0.25 x 0.10 m bricks with 12 mm mortar, each brick its own shade.
      const double course = std::floor(p.z() / 0.10);
      const double offset = std::fmod(course, 2.0) == 0 ? 0.0 : 0.125;
      const double along = p.x() + offset;
      const double col = std::floor(along / 0.25);
      const double fx = along - col * 0.25, fz = p.z() - course * 0.10;
      if (fx < 0.012 || fz < 0.012) return Eigen::Vector3f(0.55f, 0.53f, 0.48f);
      const double shade = 0.85 + 0.3 * (0.5 + 0.5 * latticeValue(static_cast<std::int64_t>(col),
                                                                 static_cast<std::int64_t>(course), 5u));
      return Eigen::Vector3f(0.45f, 0.15f, 0.08f) * static_cast<float>(shade);
    }
    case kTiles: {
      const double fx = p.x() / 0.6 - std::floor(p.x() / 0.6);
      const double fy = p.y() / 0.6 - std::floor(p.y() / 0.6);
      if (fx < 0.015 || fy < 0.015) return Eigen::Vector3f(0.5f, 0.5f, 0.5f);
      const bool dark = (static_cast<long>(std::floor(p.x() / 0.6)) +
                         static_cast<long>(std::floor(p.y() / 0.6))) % 2 != 0;
      return dark ? Eigen::Vector3f(0.20f, 0.19f, 0.24f) : Eigen::Vector3f(0.34f, 0.32f, 0.38f);
    }
  }
  return Eigen::Vector3f(0.5f, 0.5f, 0.5f);
}

struct CgBox {
  Eigen::Vector3d lo, hi;
  int material;
};

// A few axis-aligned boxes as one primitive (the pillar; the table top and its legs).
class CgBoxesPrimitive final : public Primitive {
 public:
  explicit CgBoxesPrimitive(std::vector<CgBox> boxes, int object) : boxes_(std::move(boxes)), object_(object) {
    Eigen::AlignedBox3d all;
    for (const auto& b : boxes_) {
      all.extend(b.lo);
      all.extend(b.hi);
    }
    bound_centre = all.center();
    bound_radius = 0.5 * all.diagonal().norm() + 1e-9;
  }
  bool intersect(const Ray& ray, double t_min, Hit& hit) const override {
    bool found = false;
    for (const CgBox& b : boxes_) {
      double t0 = t_min, t1 = hit.t;
      int axis = -1;
      bool ok = true;
      for (int a = 0; a < 3 && ok; ++a) {
        const double inv = 1.0 / ray.dir[a];
        double ta = (b.lo[a] - ray.origin[a]) * inv, tb = (b.hi[a] - ray.origin[a]) * inv;
        if (ta > tb) std::swap(ta, tb);
        if (ta > t0) {
          t0 = ta;
          axis = a;
        }
        t1 = std::min(t1, tb);
        ok = t0 <= t1;
      }
      if (!ok || axis < 0) continue;  // axis < 0: origin inside the box (not a camera case)
      hit.t = t0;
      hit.cls = ObjectClass::kCg;
      hit.object = object_;
      hit.normal = Eigen::Vector3d::Zero();
      hit.normal[axis] = ray.dir[axis] > 0 ? -1 : 1;
      found = true;
    }
    return found;
  }
  void shade(const Ray& ray, Hit& hit) const override {
    const Eigen::Vector3d p = ray.origin + hit.t * ray.dir;
    // Find the box the point lies on (the nearest surface) to pick its material.
    int material = boxes_.front().material;
    double best = std::numeric_limits<double>::infinity();
    for (const auto& b : boxes_) {
      const Eigen::Vector3d outside = (b.lo - p).cwiseMax(p - b.hi).cwiseMax(0.0);
      const double dist = outside.norm();
      if (dist < best) {
        best = dist;
        material = b.material;
      }
    }
    hit.rgb = shadeDiffuse(cgAlbedo(material, p), p, hit.normal);
  }

 private:
  std::vector<CgBox> boxes_;
  int object_;
};

// The CG floor (z = 0) and back wall (y = +3): they replace the cyclorama in CG renders.
class CgBackdropPrimitive final : public Primitive {
 public:
  static constexpr double kWallY = 3.0, kWallHalfWidth = 8.0, kWallHeight = 5.0, kFloorHalf = 40.0;
  bool intersect(const Ray& ray, double t_min, Hit& hit) const override {
    bool found = false;
    if (ray.dir.y() != 0) {
      const double t = (kWallY - ray.origin.y()) / ray.dir.y();
      const Eigen::Vector3d q = ray.origin + t * ray.dir;
      if (t > t_min && t < hit.t && std::abs(q.x()) <= kWallHalfWidth && q.z() >= 0 && q.z() <= kWallHeight) {
        hit.t = t;
        hit.cls = ObjectClass::kCg;
        hit.object = 3;
        hit.normal = Eigen::Vector3d(0, ray.dir.y() > 0 ? -1 : 1, 0);
        found = true;
      }
    }
    if (ray.dir.z() < 0) {
      const double t = -ray.origin.z() / ray.dir.z();
      const Eigen::Vector3d q = ray.origin + t * ray.dir;
      if (t > t_min && t < hit.t && std::abs(q.x()) <= kFloorHalf && std::abs(q.y()) <= kFloorHalf) {
        hit.t = t;
        hit.cls = ObjectClass::kCg;
        hit.object = 2;
        hit.normal = Eigen::Vector3d::UnitZ();
        found = true;
      }
    }
    return found;
  }
  void shade(const Ray& ray, Hit& hit) const override {
    const Eigen::Vector3d p = ray.origin + hit.t * ray.dir;
    hit.rgb = shadeDiffuse(cgAlbedo(hit.object == 3 ? kBrick : kTiles, p), p, hit.normal);
  }
};

}  // namespace

void ShadowCasters::add(std::vector<Capsule> capsules) {
  if (capsules.empty()) return;
  ShadowGroup g;
  Eigen::AlignedBox3d box;
  for (const auto& c : capsules) {
    box.extend(c.a);
    box.extend(c.b);
  }
  g.bound_centre = box.center();
  for (const auto& c : capsules)
    g.bound_radius = std::max({g.bound_radius, (c.a - g.bound_centre).norm() + c.r,
                               (c.b - g.bound_centre).norm() + c.r});
  g.capsules = std::move(capsules);
  groups.push_back(std::move(g));
}

double keyVisibility(const ShadowCasters& casters, const Eigen::Vector3d& p) {
  // Soft shadow of a disc light: an occluder at fraction s of the way from p to the light
  // centre blocks the part of the light's cone cross-section (radius kKeyLightRadius * s)
  // that its own cross-section (a disc of its radius, centred at the closest approach)
  // covers. Occluders combine as independent blockers.
  const Eigen::Vector3d to_light = kKeyLightCentre - p;
  const double inv_len2 = 1.0 / to_light.squaredNorm();
  const double inv_len = std::sqrt(inv_len2);
  // Conservative: does a sphere (c, r) come within reach of the cone from p to the light?
  auto nearCone = [&](const Eigen::Vector3d& c, double r) {
    const Eigen::Vector3d pc = c - p;
    const double along = pc.dot(to_light) * inv_len2;  // fraction of the way to the light
    if (along < -r * inv_len || along > 1 + r * inv_len) return false;
    const double s0 = std::clamp(along, 0.0, 1.0);
    const double d2 = (pc - s0 * to_light).squaredNorm();
    const double reach = r + kKeyLightRadius * std::min(1.0, s0 + r * inv_len);
    return d2 <= reach * reach;
  };
  double visibility = 1.0;
  for (const ShadowGroup& g : casters.groups) {
    if (!nearCone(g.bound_centre, g.bound_radius)) continue;
    for (const Capsule& c : g.capsules) {
      if (!nearCone(0.5 * (c.a + c.b), 0.5 * (c.b - c.a).norm() + c.r)) continue;
      double s, t;
      const double d = segmentSegmentDistance(p, kKeyLightCentre, c.a, c.b, s, t);
      const double w = std::max(kKeyLightRadius * s, 1e-5);
      if (d >= w + c.r) continue;
      const double blocked = areaOfLens(w, c.r, d) / (kPi * w * w);
      visibility *= 1.0 - std::clamp(blocked, 0.0, 1.0);
    }
  }
  return visibility;
}

std::shared_ptr<const Primitive> makeStagePrimitive(const StudioConfig& config, ShadowCasters casters) {
  return std::make_shared<StagePrimitive>(config, std::move(casters));
}

void addCgSet(Scene& scene, bool with_backdrop) {
  // Pillar: 0.5 m square, 3 m high, at (0.3, -0.6): between the main camera (y ~ -6) and the
  // back half of the actor's path.
  scene.add(std::make_shared<CgBoxesPrimitive>(
      std::vector<CgBox>{{Eigen::Vector3d(0.05, -0.85, 0), Eigen::Vector3d(0.55, -0.35, 3.0), kStone}}, 0));
  // Table: 1.2 x 0.7 m top at 0.8 m, centred at (-1.3, -0.3).
  const Eigen::Vector3d c(-1.3, -0.3, 0);
  std::vector<CgBox> table = {{c + Eigen::Vector3d(-0.6, -0.35, 0.75), c + Eigen::Vector3d(0.6, 0.35, 0.80), kWood}};
  for (double sx : {-1.0, 1.0})
    for (double sy : {-1.0, 1.0}) {
      const Eigen::Vector3d leg = c + Eigen::Vector3d(sx * 0.52, sy * 0.27, 0);
      table.push_back({leg + Eigen::Vector3d(-0.03, -0.03, 0), leg + Eigen::Vector3d(0.03, 0.03, 0.75), kDarkWood});
    }
  scene.add(std::make_shared<CgBoxesPrimitive>(std::move(table), 1));
  if (with_backdrop) scene.add(std::make_shared<CgBackdropPrimitive>());
}

}  // namespace previz::synth::detail
