// Ray-mesh intersection for the studio truth (the mesh types and files live in core/mesh.h).
#include <cmath>
#include <limits>

#include "datasets/studio.h"

namespace previz::synth {

double intersectMesh(const TriangleMesh& mesh, const Ray& ray) {
  // Möller & Trumbore 1997, both faces, in double precision.
  double best = std::numeric_limits<double>::infinity();
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d v0 = mesh.vertices[f[0]].cast<double>();
    const Eigen::Vector3d e1 = mesh.vertices[f[1]].cast<double>() - v0;
    const Eigen::Vector3d e2 = mesh.vertices[f[2]].cast<double>() - v0;
    const Eigen::Vector3d pvec = ray.dir.cross(e2);
    const double det = e1.dot(pvec);
    if (std::abs(det) < 1e-18) continue;
    const double inv = 1.0 / det;
    const Eigen::Vector3d tvec = ray.origin - v0;
    const double u = tvec.dot(pvec) * inv;
    if (u < 0 || u > 1) continue;
    const Eigen::Vector3d qvec = tvec.cross(e1);
    const double v = ray.dir.dot(qvec) * inv;
    if (v < 0 || u + v > 1) continue;
    const double t = e2.dot(qvec) * inv;
    if (t > 1e-9 && t < best) best = t;
  }
  return best;
}

}  // namespace previz::synth
