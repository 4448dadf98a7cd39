#include "carving/volume.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>

#include "core/error.h"

namespace previz::carving {

FoundVolume volumeFromSilhouettes(const std::vector<RigCamera>& cameras, const Silhouettes& silhouettes,
                                  const HullOptions& options) {
  if (cameras.size() < 2) throw Error("a volume needs at least two cameras", fieldContext("volume"));
  // Nearest point to the optical axes: sum (I - d d^T) (p - C) = 0.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const RigCamera& rc : cameras) {
    const Eigen::Vector3d C = rc.T_world_cam.translation();
    const Eigen::Vector3d d = rc.T_world_cam.rotation().col(2).normalized();
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * C;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  if (eig.eigenvalues().minCoeff() < 1e-3 * eig.eigenvalues().maxCoeff())
    throw Error("the cameras' optical axes are nearly parallel: no common point they look at; give the volume",
                fieldContext("volume"));
  FoundVolume found;
  found.look_at = A.ldlt().solve(b);
  std::vector<double> distances;
  for (const RigCamera& rc : cameras) distances.push_back((rc.T_world_cam.translation() - found.look_at).norm());
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  found.radius = distances[distances.size() / 2];

  constexpr int kCells = 64;
  HullOptions coarse = options;
  coarse.volume = Eigen::AlignedBox3d(found.look_at - Eigen::Vector3d::Constant(found.radius),
                                      found.look_at + Eigen::Vector3d::Constant(found.radius));
  coarse.voxel_m = 2.0 * found.radius / kCells;
  // Seen by half the cameras at least: a cell just in front of one camera lies inside its
  // silhouette and outside the views of the cameras beside it, so few cameras judge it and it
  // survives; what the rig looks at is seen by most of it.
  coarse.min_views = std::max(options.min_views, static_cast<int>((cameras.size() + 1) / 2));
  Carver carver(cameras, coarse);
  const VisualHull hull = carver.carve(silhouettes);
  Eigen::AlignedBox3d box;
  // A kept cell counts when its centre passes the exact point test: a cell only partly in a
  // camera's image is "mixed" to it, never carved by it, and a rig whose views are narrow
  // windows (the dino's principal points lie far above its images) keeps most of the cube so.
  auto add = [&](const HullCell& c) {
    const double edge = hull.voxel_m * std::pow(2.0, c.level);
    const Eigen::Vector3d lo = hull.origin + edge * c.index.cast<double>();
    if (!carver.inside(hull, lo + Eigen::Vector3d::Constant(0.5 * edge))) return;
    box.extend(lo);
    box.extend(lo + Eigen::Vector3d::Constant(edge));
    ++found.coarse_cells;
  };
  for (const HullCell& c : hull.inside) add(c);
  for (const HullCell& c : hull.surface) add(c);
  if (box.isEmpty())
    throw Error("the silhouettes' cones do not meet within " + std::to_string(found.radius) +
                    " of the point the cameras look at: check the rig and the keys, or give the volume",
                fieldContext("volume"));
  // Parts thinner than a cell (a tail's tip, spikes) hold no passing centre: three cells of margin.
  box.min() -= Eigen::Vector3d::Constant(3 * coarse.voxel_m);
  box.max() += Eigen::Vector3d::Constant(3 * coarse.voxel_m);
  found.box = box;
  return found;
}

}  // namespace previz::carving
