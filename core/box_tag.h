#pragma once
// Where a tag sits on a face of a box prop: the convention props.json's "face" tags
// (tracking/props.h) and the synthetic studio's crate (datasets/studio_prop.cpp) share.
#include <Eigen/Core>

#include "core/pose.h"

namespace previz {

// n = the face's outward normal in the prop frame (a unit axis), half = the box's half sizes.
// The tag's z points into the face; its y points down: -z of the prop on the side faces (the
// tag reads upright with the prop's +z up), -y on the top and bottom faces (+y away from a
// viewer standing at -y). Returns T_prop_tag, centred on the face.
Pose boxFaceTagPose(const Eigen::Vector3d& n, const Eigen::Vector3d& half);

}  // namespace previz
