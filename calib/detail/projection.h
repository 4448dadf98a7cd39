#pragma once
// The projection the intrinsic solve, view selection and uncertainty maps differentiate:
// core/camera.h's camera (its lens model of core/lens_model.h, skew included) with Ceres' Jets
// flowing through it. Internal to previz_calib.
#include <cmath>

#include <Eigen/Core>
#include <ceres/jet.h>
#include <ceres/rotation.h>

#include "core/camera.h"
#include "core/lens_model.h"

namespace previz::calib::detail {

// Intrinsic vector layout, shared by the solve, the covariance and the reports. The lens model
// (Camera::dist.model) says which distortion slots are used: Brown–Conrady k1 k2 p1 p2 k3 and
// its rational k4 k5 k6 (held unless asked for), Kannala–Brandt k1 k2 k3 k4 (p1 p2 k5 k6 held at
// 0); it travels beside the vector.
enum IntrinsicIndex { kFx = 0, kFy, kCx, kCy, kSkew, kK1, kK2, kP1, kP2, kK3, kK4, kK5, kK6, kIntrinsicCount };

inline void cameraToVector(const Camera& c, double* v) {
  v[kFx] = c.fx;
  v[kFy] = c.fy;
  v[kCx] = c.cx;
  v[kCy] = c.cy;
  v[kSkew] = c.skew;
  v[kK1] = c.dist.k1;
  v[kK2] = c.dist.k2;
  v[kP1] = c.dist.p1;
  v[kP2] = c.dist.p2;
  v[kK3] = c.dist.k3;
  v[kK4] = c.dist.k4;
  v[kK5] = c.dist.k5;
  v[kK6] = c.dist.k6;
}

inline void vectorToCamera(const double* v, LensModel model, Camera& c) {
  c.dist.model = model;
  c.fx = v[kFx];
  c.fy = v[kFy];
  c.cx = v[kCx];
  c.cy = v[kCy];
  c.skew = v[kSkew];
  c.dist.k1 = v[kK1];
  c.dist.k2 = v[kK2];
  c.dist.p1 = v[kP1];
  c.dist.p2 = v[kP2];
  c.dist.k3 = v[kK3];
  c.dist.k4 = v[kK4];
  c.dist.k5 = v[kK5];
  c.dist.k6 = v[kK6];
}

// Camera-frame point -> pixel. fy is intr[kFy] unless aspect > 0, in which case fy = aspect * fx
// (the fix_aspect lock ties the two instead of freezing fy).
template <typename T>
inline void projectCameraPoint(const T* intr, const T* p, double aspect, LensModel model, T* uv) {
  const T x = p[0] / p[2];
  const T y = p[1] / p[2];
  T xd, yd;
  if (model == LensModel::kKannalaBrandt)
    lens::kannalaBrandtDistort(intr[kK1], intr[kK2], intr[kK3], intr[kK4], x, y, xd, yd);
  else
    lens::brownDistort(intr[kK1], intr[kK2], intr[kP1], intr[kP2], intr[kK3], intr[kK4], intr[kK5], intr[kK6], x, y,
                       xd, yd);
  const T fy = aspect > 0 ? T(aspect) * intr[kFx] : intr[kFy];
  uv[0] = intr[kFx] * xd + intr[kSkew] * yd + intr[kCx];
  uv[1] = fy * yd + intr[kCy];
}

// Board point -> pixel through pose = (angle-axis, translation) of T_cam_board.
template <typename T>
inline void projectBoardPoint(const T* intr, const T* pose, const T* p_board, double aspect, LensModel model,
                              T* uv) {
  T p[3];
  ceres::AngleAxisRotatePoint(pose, p_board, p);
  p[0] += pose[3];
  p[1] += pose[4];
  p[2] += pose[5];
  projectCameraPoint(intr, p, aspect, model, uv);
}

// Pixel and its Jacobian with respect to [intrinsics (13), pose (6)] for one board point.
inline Eigen::Vector2d projectBoardPointJacobian(const double* intr, const double* pose,
                                                 const Eigen::Vector3d& p_board, double aspect, LensModel model,
                                                 Eigen::Matrix<double, 2, kIntrinsicCount + 6>& J) {
  using Jet = ceres::Jet<double, kIntrinsicCount + 6>;
  Jet ji[kIntrinsicCount], jp[6];
  for (int i = 0; i < kIntrinsicCount; ++i) ji[i] = Jet(intr[i], i);
  for (int i = 0; i < 6; ++i) jp[i] = Jet(pose[i], kIntrinsicCount + i);
  const Jet pb[3] = {Jet(p_board.x()), Jet(p_board.y()), Jet(p_board.z())};
  Jet uv[2];
  projectBoardPoint(ji, jp, pb, aspect, model, uv);
  J.row(0) = uv[0].v.transpose();
  J.row(1) = uv[1].v.transpose();
  return Eigen::Vector2d(uv[0].a, uv[1].a);
}

// Pixel of a camera-frame point and its Jacobian with respect to the intrinsics (the ray held).
inline Eigen::Vector2d projectCameraPointJacobian(const double* intr, const Eigen::Vector3d& p,
                                                  double aspect, LensModel model,
                                                  Eigen::Matrix<double, 2, kIntrinsicCount>& J) {
  using Jet = ceres::Jet<double, kIntrinsicCount>;
  Jet ji[kIntrinsicCount];
  for (int i = 0; i < kIntrinsicCount; ++i) ji[i] = Jet(intr[i], i);
  const Jet pc[3] = {Jet(p.x()), Jet(p.y()), Jet(p.z())};
  Jet uv[2];
  projectCameraPoint(ji, pc, aspect, model, uv);
  J.row(0) = uv[0].v.transpose();
  J.row(1) = uv[1].v.transpose();
  return Eigen::Vector2d(uv[0].a, uv[1].a);
}

}  // namespace previz::calib::detail
