// The synthetic studio's content at time t. World layout (metres, z up, floor z = 0):
//   stage      acting area |x|, |y| <= stage_size/2 (4 m) centred on the origin
//   cyclorama  green floor |x|, |y| <= cyc/2 (16 m), walls at y = +cyc/2 and x = -cyc/2
//              (height wall_height_m) with 0.6 m coves; beyond: dark studio box 30 x 30 x 9 m
//   key light  disc of radius 1 m at (0.6, -0.9, 6.0) facing down (shading and soft shadows)
//   actor      walks (-1.7, 0.9) -> behind the pillar -> (1.35, -1.15) in the first 48 % of
//              the take, stops, raises both arms, turns ~80 degrees on the spot, walks along
//              the front (y ~ -1.5, in front of the pillar) to (-1.6, -1.2)
//   prop       0.3 m crate on an invisible grip, 1.1–1.45 m high, (-0.9, -1.1) -> (1.0, 0.6)
//   CG set     pillar 0.5 x 0.5 x 3 m at (0.3, -0.6); table 1.2 x 0.7 x 0.8 m at (-1.3, -0.3);
//              back wall y = +3 (|x| <= 8, 5 m high) and tiled floor, replacing the cyclorama
//              when rendered without the stage
#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "datasets/detail/studio_detail.h"

namespace previz::synth {

namespace {

void checkConfig(const StudioConfig& c) {
  auto fail = [](const std::string& field, const std::string& what) {
    ErrorContext context;
    context.field = field;
    return Error("studio: " + field + " " + what, context);
  };
  auto num = [](double v) {
    std::ostringstream s;
    s << v;
    return s.str();
  };
  if (!(c.stage_size_m > 0 && std::isfinite(c.stage_size_m)))
    throw fail("stage_size_m", "must be > 0 (got " + num(c.stage_size_m) + ")");
  // The actor's and prop's paths use the central 4 m x 4 m; the cyclorama must contain them
  // with room for the coves and fit inside the 30 m studio.
  if (!(c.cyc_size_m >= std::max(6.0, c.stage_size_m + 2.0) && c.cyc_size_m <= 28.0))
    throw fail("cyc_size_m", "must be in [max(6, stage_size_m + 2), 28] (got " + num(c.cyc_size_m) + ")");
  if (!(c.wall_height_m >= 1.0 && c.wall_height_m <= 8.5))
    throw fail("wall_height_m", "must be in [1, 8.5] (got " + num(c.wall_height_m) + ")");
  if (!(c.take_duration_s >= 2.0 && std::isfinite(c.take_duration_s)))
    throw fail("take_duration_s", "must be >= 2 s (got " + num(c.take_duration_s) + ")");
}

}  // namespace

const char* toString(Backdrop backdrop) {
  switch (backdrop) {
    case Backdrop::kGreen: return "green";
    case Backdrop::kBlue: return "blue";
    case Backdrop::kSet: return "set";
  }
  return "?";
}

Backdrop backdropFromString(const std::string& name) {
  for (Backdrop b : {Backdrop::kGreen, Backdrop::kBlue, Backdrop::kSet})
    if (name == toString(b)) return b;
  ErrorContext context;
  context.field = "backdrop";
  throw Error("studio: unknown backdrop '" + name + "' (green, blue or set)", context);
}

Studio::Studio(const StudioConfig& config) : config_(config), prop_(detail::makePropSpec()) {
  checkConfig(config_);
}

Scene Studio::sceneAt(double time_s, unsigned layers) const {
  Scene scene;
  const bool actor = config_.with_actor && (layers & kLayerActor);
  const bool prop = config_.with_prop && (layers & kLayerProp);
  detail::ActorPose pose;
  if (actor) pose = detail::actorPoseAt(config_, time_s);
  Pose T_world_prop = Pose::Identity();
  if (prop) T_world_prop = this->T_world_prop(time_s);

  if (actor) scene.add(detail::makeActorPrimitive(pose));
  if (prop) scene.add(detail::makePropPrimitive(prop_, T_world_prop));
  if (layers & kLayerCg) detail::addCgSet(scene, !(layers & kLayerStage));
  if (layers & kLayerStage) {
    // Shadows on the screen come from what is physically in this scene.
    detail::ShadowCasters casters;
    if (actor) casters.add(std::vector<detail::Capsule>(pose.parts.begin(), pose.parts.end()));
    if (prop) {
      // The crate as a sphere of about its mean half-extent: a soft shadow needs no more.
      const Eigen::Vector3d c = T_world_prop.translation();
      casters.add({{c, c, 0.55 * prop_.box_size_m.mean()}});
    }
    scene.add(detail::makeStagePrimitive(config_, std::move(casters)));
  } else if (layers & kLayerCg) {
    scene.environment_rgb = Eigen::Vector3f(0.30f, 0.38f, 0.52f);  // CG sky beyond the set
  }
  return scene;
}

TriangleMesh Studio::actorMesh(double time_s) const {
  TriangleMesh mesh;
  if (!config_.with_actor) return mesh;
  const detail::ActorPose pose = detail::actorPoseAt(config_, time_s);
  // Half of the 0.3 mm budget per direction: around the axis and along the meridians.
  constexpr double kSagittaM = 0.14e-3;
  for (const auto& c : pose.parts) {
    const TriangleMesh part = detail::capsuleMesh(c, kSagittaM);
    const int base = static_cast<int>(mesh.vertices.size());
    mesh.vertices.insert(mesh.vertices.end(), part.vertices.begin(), part.vertices.end());
    mesh.normals.insert(mesh.normals.end(), part.normals.begin(), part.normals.end());
    for (const auto& f : part.faces) mesh.faces.push_back(f + Eigen::Vector3i::Constant(base));
  }
  return mesh;
}

Eigen::AlignedBox3d Studio::actorBounds(double time_s) const {
  Eigen::AlignedBox3d box;
  if (!config_.with_actor) return box;
  const detail::ActorPose pose = detail::actorPoseAt(config_, time_s);
  for (const auto& c : pose.parts) {
    box.extend(c.a.cwiseMin(c.b) - Eigen::Vector3d::Constant(c.r));
    box.extend(c.a.cwiseMax(c.b) + Eigen::Vector3d::Constant(c.r));
  }
  return box;
}

Pose Studio::T_world_prop(double time_s) const { return detail::propPathAt(config_, time_s); }

}  // namespace previz::synth
