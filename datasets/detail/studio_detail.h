#pragma once
// Private pieces of the synthetic studio (datasets/studio_*.cpp): the actor's kinematics, the
// primitives of the stage, prop, boards and CG set, and the one lighting model they share.
// Nothing here is part of the public API.
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "core/pose.h"
#include "datasets/scene.h"
#include "datasets/studio.h"

namespace previz::synth::detail {

// ---------------------------------------------------------------------------------------------
// Lighting. One overhead soft box (a disc light facing down) plus a uniform fill, shared by
// every object so the plate is consistent: the actor's floor shadow is cast by the same light
// that shades the actor.
inline const Eigen::Vector3d kKeyLightCentre(0.6, -0.9, 6.0);
constexpr double kKeyLightRadius = 1.0;  // metres; sets the penumbra width
constexpr double kKeyLightGain = 0.60;   // key contribution on a floor point under the light
constexpr double kFillLight = 0.45;      // uniform fill (cyclorama light banks, bounce)

// Key irradiance factor at p with unit normal n (before shadowing): Lambert cosine times a
// smooth distance falloff normalised to 1 at the stage centre.
inline double keyLight(const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
  const Eigen::Vector3d to_light = kKeyLightCentre - p;
  const double d2 = to_light.squaredNorm();
  const double cos_theta = n.dot(to_light) / std::sqrt(d2);
  if (cos_theta <= 0) return 0;
  constexpr double kFalloff2 = 60.0;  // m^2: half intensity ~8 m from the light
  const double d2_centre = kKeyLightCentre.squaredNorm();
  return cos_theta * (1.0 + d2_centre / kFalloff2) / (1.0 + d2 / kFalloff2);
}

// Diffuse shading used by actor, prop, boards and the CG set.
inline Eigen::Vector3f shadeDiffuse(const Eigen::Vector3f& albedo, const Eigen::Vector3d& p,
                                    const Eigen::Vector3d& n) {
  const double light = kFillLight + kKeyLightGain * keyLight(p, n);
  return (albedo * static_cast<float>(light)).cwiseMin(1.0f);
}

// Cheap deterministic hash noise (32-bit; the studio's textures only need it to look random
// and to be a pure function of seed and position).
inline std::uint32_t hash32(std::uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}
inline double latticeValue(std::int64_t ix, std::int64_t iy, std::uint32_t seed) {
  const std::uint32_t h = hash32(static_cast<std::uint32_t>(ix) * 0x8DA6B343u ^
                                 static_cast<std::uint32_t>(iy) * 0xD8163841u ^ seed);
  return (h >> 8) * (1.0 / 16777216.0) * 2.0 - 1.0;  // [-1, 1)
}
// Bilinear value noise in [-1, 1], feature size 'cell' metres.
inline double valueNoise(double u, double v, double cell, std::uint32_t seed) {
  const double x = u / cell, y = v / cell;
  const double fx = std::floor(x), fy = std::floor(y);
  const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy);
  double tx = x - fx, ty = y - fy;
  tx = tx * tx * (3 - 2 * tx);
  ty = ty * ty * (3 - 2 * ty);
  const double a = latticeValue(ix, iy, seed), b = latticeValue(ix + 1, iy, seed);
  const double c = latticeValue(ix, iy + 1, seed), d = latticeValue(ix + 1, iy + 1, seed);
  return (a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * ty;
}

// ---------------------------------------------------------------------------------------------
// Actor: capsules (segment a-b swept by radius r; a sphere when a == b).
enum ActorPart : int {
  kHead, kNeck, kTorso, kPelvis, kBackpack,
  kUpperArmL, kLowerArmL, kHandL, kUpperArmR, kLowerArmR, kHandR,
  kUpperLegL, kLowerLegL, kFootL, kUpperLegR, kLowerLegR, kFootR,
  kActorPartCount
};
const char* actorPartName(int part);

struct Capsule {
  Eigen::Vector3d a = Eigen::Vector3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  double r = 0;
};

struct ActorPose {
  std::array<Capsule, kActorPartCount> parts;
  Eigen::Vector3d pelvis = Eigen::Vector3d::Zero();  // pelvis centre (world)
  double heading = 0;        // radians, direction the actor faces (0 = +x, pi/2 = +y)
  double speed = 0;          // m/s along the path
  double arms_raised = 0;    // 0 = down, 1 = fully raised
  Eigen::Vector3d bound_centre = Eigen::Vector3d::Zero();
  double bound_radius = 0;   // sphere containing every part
};

ActorPose actorPoseAt(const StudioConfig& config, double time_s);
Eigen::Vector3f actorAlbedo(int part);  // linear RGB (the head's hair is decided in shade())

std::shared_ptr<const Primitive> makeActorPrimitive(const ActorPose& pose);
TriangleMesh capsuleMesh(const Capsule& c, double max_sagitta_m);

// Closest distance between segments p0-p1 and q0-q1; s, t are the parameters in [0, 1] of the
// closest points.
double segmentSegmentDistance(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                              const Eigen::Vector3d& q0, const Eigen::Vector3d& q1, double& s,
                              double& t);

// ---------------------------------------------------------------------------------------------
// Stage (cyclorama + the dark studio beyond it) with soft shadows of the occluders given.
struct ShadowGroup {  // occluders tested together after one bounding-sphere test
  std::vector<Capsule> capsules;
  Eigen::Vector3d bound_centre = Eigen::Vector3d::Zero();
  double bound_radius = 0;
};
struct ShadowCasters {
  std::vector<ShadowGroup> groups;  // the actor's parts; the prop (as a sphere)
  void add(std::vector<Capsule> capsules);  // computes the group's bound
};
std::shared_ptr<const Primitive> makeStagePrimitive(const StudioConfig& config,
                                                    ShadowCasters casters);
// Fraction of the key light that reaches p (1 = unshadowed).
double keyVisibility(const ShadowCasters& casters, const Eigen::Vector3d& p);

// CG virtual set: pillar and table always; floor and back wall when 'with_backdrop'.
void addCgSet(Scene& scene, bool with_backdrop);

// ---------------------------------------------------------------------------------------------
// Prop.
PropSpec makePropSpec();
std::shared_ptr<const Primitive> makePropPrimitive(const PropSpec& spec, const Pose& T_world_prop);
Pose propPathAt(const StudioConfig& config, double time_s);

// libapriltag's tag36h11 bitmaps, built once: 10 x 10 cells, row-major, 0 = black, 255 =
// white; the outer ring is white, the 8 x 8 square inside has the black border.
const std::uint8_t* tag36h11Bitmap(int id);  // nullptr if id is out of range
constexpr int kTagBitmapWidth = 10;
constexpr int kTagBlackWidth = 8;

// Printed black / white albedo used by tags and boards.
inline const Eigen::Vector3f kInkBlack(0.03f, 0.03f, 0.03f);
inline const Eigen::Vector3f kPaperWhite(0.82f, 0.82f, 0.80f);

}  // namespace previz::synth::detail
