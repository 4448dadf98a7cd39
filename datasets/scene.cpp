#include "datasets/scene.h"

#include <cmath>

#include "core/error.h"

namespace previz::synth {

namespace {
// Rays start at camera centres, never on a surface, so any positive distance counts.
constexpr double kTMin = 1e-9;
}  // namespace

void Scene::add(std::shared_ptr<const Primitive> primitive) {
  if (!primitive) throw Error("scene: cannot add a null primitive");
  prims_.push_back(std::move(primitive));
}

bool Scene::trace(const Ray& ray, Hit& hit) const {
  hit = Hit();
  const Primitive* winner = nullptr;
  for (const auto& owned : prims_) {
    const Primitive& prim = *owned;
    if (prim.bound_radius < std::numeric_limits<double>::infinity()) {
      // Reject when the ray's line passes outside the sphere, or the sphere lies entirely
      // behind the origin or beyond the nearest hit so far.
      const Eigen::Vector3d oc = prim.bound_centre - ray.origin;
      const double along = oc.dot(ray.dir);
      const double r = prim.bound_radius;
      if (along + r < kTMin || along - r > hit.t) continue;
      if (oc.squaredNorm() - along * along > r * r) continue;
    }
    if (prim.intersect(ray, kTMin, hit)) winner = &prim;
  }
  if (!winner) {
    hit.rgb = environment_rgb;
    return false;
  }
  winner->shade(ray, hit);
  return true;
}

}  // namespace previz::synth
