#pragma once
// The synthetic studio's world at one instant: analytic primitives that a ray can hit, each
// returning its shaded colour. Built by Studio::sceneAt() (studio.h); rendered by render.h.
// World frame: z up, floor at z = 0, metres (docs/conventions.md).
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>

namespace previz::synth {

// What a ray hit; truth masks are built from it.
enum class ObjectClass : std::uint8_t {
  kNone = 0,   // nothing (environment)
  kStage = 1,  // green cyclorama
  kActor = 2,
  kProp = 3,
  kBoard = 4,
  kCg = 5,     // virtual set objects (only in CG / composite layers)
  kStudio = 6, // the real studio beyond the cyclorama (dark, not green)
};

// Which objects a scene contains.
enum Layer : unsigned {
  kLayerStage = 1u << 0,
  kLayerActor = 1u << 1,
  kLayerProp = 1u << 2,
  kLayerBoards = 1u << 3,
  kLayerCg = 1u << 4,
  kLayersPlate = kLayerStage | kLayerActor | kLayerProp,  // what a real camera films
};

struct Ray {
  Eigen::Vector3d origin;  // world
  Eigen::Vector3d dir;     // world, unit length
};

struct Hit {
  double t = std::numeric_limits<double>::infinity();  // ray parameter (metres along dir)
  ObjectClass cls = ObjectClass::kNone;
  int object = -1;            // index of the object within its class (e.g. actor part)
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // world, facing the ray
  Eigen::Vector3f rgb = Eigen::Vector3f::Zero();      // shaded linear colour in [0, 1]
};

// One primitive: intersects a ray within (t_min, hit.t) and, when nearer, overwrites hit
// (t, cls, object, normal) and returns true. shade() fills hit.rgb for a hit it produced.
// Implementations must be thread-safe for concurrent const calls and allocate nothing.
class Primitive {
 public:
  virtual ~Primitive() = default;
  virtual bool intersect(const Ray& ray, double t_min, Hit& hit) const = 0;
  virtual void shade(const Ray& ray, Hit& hit) const = 0;
  // Conservative world bounding sphere for early rejection (radius +inf = unbounded).
  Eigen::Vector3d bound_centre = Eigen::Vector3d::Zero();
  double bound_radius = std::numeric_limits<double>::infinity();
};

class Scene {
 public:
  void add(std::shared_ptr<const Primitive> primitive);
  // Nearest hit along the ray (shaded). Returns false when nothing is hit (hit.cls = kNone,
  // hit.rgb = environment colour).
  bool trace(const Ray& ray, Hit& hit) const;
  // Colour returned for rays that hit nothing.
  Eigen::Vector3f environment_rgb = Eigen::Vector3f(0.02f, 0.02f, 0.02f);
  const std::vector<std::shared_ptr<const Primitive>>& primitives() const { return prims_; }

 private:
  std::vector<std::shared_ptr<const Primitive>> prims_;
};

}  // namespace previz::synth
