// The world's scale against tags of known size (see scale.h).
#include "tracking/scale.h"
#include "core/stats.h"

#include <algorithm>
#include <cmath>
#include <map>

#include <Eigen/SVD>

namespace previz::tracking {

namespace {

struct Sighting {
  Eigen::Matrix<double, 3, 4> P;  // [R | t] of the camera, world -> camera
  Eigen::Vector2d x;              // undistorted normalised coordinates of the corner
};

// Linear triangulation (DLT) of one point from two or more normalised sightings.
Eigen::Vector3d triangulate(const std::vector<Sighting>& s) {
  Eigen::MatrixXd A(2 * s.size(), 4);
  for (size_t i = 0; i < s.size(); ++i) {
    A.row(2 * i) = s[i].x.x() * s[i].P.row(2) - s[i].P.row(0);
    A.row(2 * i + 1) = s[i].x.y() * s[i].P.row(2) - s[i].P.row(1);
  }
  const Eigen::Vector4d X = Eigen::JacobiSVD<Eigen::MatrixXd>(A, Eigen::ComputeFullV).matrixV().col(3);
  return X.head<3>() / X(3);
}

}  // namespace

ScaleCheck measureScale(const std::vector<ScaleFrame>& frames, const PropSet& props, const DetectorOptions& detector) {
  DetectorOptions d = detector;
  d.families = props.families();
  if (d.families.empty()) return {};
  TagDetector tags(d);
  ScaleCheck out;
  std::vector<double> ratios;
  for (const ScaleFrame& f : frames) {
    // (prop, tag, corner) -> its sightings.
    std::map<std::array<int, 3>, std::vector<Sighting>> corners;
    for (size_t c = 0; c < f.cameras.size() && c < f.images.size(); ++c) {
      if (f.images[c].empty()) continue;
      const RigCamera& rc = f.cameras[c];
      const Pose T_cam_world = rc.T_world_cam.inverse();
      Eigen::Matrix<double, 3, 4> P;
      P.leftCols<3>() = T_cam_world.linear();
      P.col(3) = T_cam_world.translation();
      for (const TagDetection& det : tags.detect(f.images[c])) {
        const auto owner = props.findTag(det.family, det.id);
        if (!owner) continue;
        for (int k = 0; k < 4; ++k) {
          const InverseResult x = rc.camera.undistort(rc.camera.pixelToNormalized(det.corners_px[k]));
          if (!x.ok()) continue;
          corners[{owner->first, owner->second, k}].push_back({P, x.point});
        }
      }
    }
    bool any = false;
    for (size_t p = 0; p < props.props.size(); ++p) {
      for (size_t t = 0; t < props.props[p].tags.size(); ++t) {
        std::array<Eigen::Vector3d, 4> X;
        bool all = true;
        for (int k = 0; k < 4 && all; ++k) {
          const auto it = corners.find({static_cast<int>(p), static_cast<int>(t), k});
          all = it != corners.end() && it->second.size() >= 2;
          if (all) X[k] = triangulate(it->second);
        }
        if (!all) continue;
        const double size = props.props[p].tags[t].size_m;
        for (int k = 0; k < 4; ++k) ratios.push_back((X[(k + 1) % 4] - X[k]).norm() / size);
        ++out.tags;
        any = true;
      }
    }
    if (any) out.frames.push_back(f.frame);
  }
  out.edges = static_cast<int>(ratios.size());
  out.ratio = median(ratios);
  std::vector<double> dev;
  for (double r : ratios) dev.push_back(std::abs(r - out.ratio));
  out.spread = median(dev);
  return out;
}

}  // namespace previz::tracking
