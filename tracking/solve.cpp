// Joint rigid pose solve over every corner of every view (see solve.h).
#include "tracking/solve.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/error.h"
#include "core/units.h"

namespace previz::tracking {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// One corner: the fixed point X and where a camera saw it (ideal normalized m). For a prop,
// X is in the prop frame and the camera maps world to camera by (RA, tA); for a camera solve,
// X is in the world.
struct Corner {
  int camera = 0;
  Eigen::Vector3d X;
  Eigen::Vector2d m;
  double f = 1;  // mean focal length (px per normalized unit): residuals in pixels
  Eigen::Matrix3d RA = Eigen::Matrix3d::Identity();
  Eigen::Vector3d tA = Eigen::Vector3d::Zero();
};

// Pose parametrisation around R0: R = Exp(w) R0, t = t. Prop: X_cam = RA (R X + t) + tA.
// Camera (invert): the pose is T_world_cam and X_cam = R^T (X - t).
struct CornerCost {
  CornerCost(const Corner& c, const Eigen::Matrix3d& R0, bool invert) : c_(c), R0_(R0), invert_(invert) {}
  template <typename T>
  bool operator()(const T* w, const T* t, T* r) const {
    T xc[3];
    if (!invert_) {
      const Eigen::Vector3d y = R0_ * c_.X;
      const T yv[3] = {T(y.x()), T(y.y()), T(y.z())};
      T z[3];
      ceres::AngleAxisRotatePoint(w, yv, z);
      for (int i = 0; i < 3; ++i) z[i] += t[i];
      for (int i = 0; i < 3; ++i)
        xc[i] = T(c_.RA(i, 0)) * z[0] + T(c_.RA(i, 1)) * z[1] + T(c_.RA(i, 2)) * z[2] + T(c_.tA[i]);
    } else {
      const T d[3] = {T(c_.X.x()) - t[0], T(c_.X.y()) - t[1], T(c_.X.z()) - t[2]};
      const T mw[3] = {-w[0], -w[1], -w[2]};
      T e[3];
      ceres::AngleAxisRotatePoint(mw, d, e);
      for (int i = 0; i < 3; ++i)  // R0^T e
        xc[i] = T(R0_(0, i)) * e[0] + T(R0_(1, i)) * e[1] + T(R0_(2, i)) * e[2];
    }
    if (xc[2] <= T(1e-9)) xc[2] = T(1e-9);  // behind the camera: a large residual, not a NaN
    r[0] = T(c_.f) * (xc[0] / xc[2] - T(c_.m.x()));
    r[1] = T(c_.f) * (xc[1] / xc[2] - T(c_.m.y()));
    return true;
  }
  Corner c_;
  Eigen::Matrix3d R0_;
  bool invert_;
};

Eigen::Vector3d cameraPoint(const Corner& c, const Pose& T, bool invert) {
  return invert ? Eigen::Vector3d(T.linear().transpose() * (c.X - T.translation()))
                : Eigen::Vector3d(c.RA * (T * c.X) + c.tA);
}

double errorPx(const Corner& c, const Pose& T, bool invert) {
  const Eigen::Vector3d p = cameraPoint(c, T, invert);
  if (p.z() <= 1e-9) return kInf;
  return c.f * (p.head<2>() / p.z() - c.m).norm();
}

// Robust score of a candidate over every corner (capped squared pixels).
double score(const std::vector<Corner>& corners, const Pose& T, bool invert) {
  constexpr double kCapPx = 10.0;
  double s = 0;
  for (const Corner& c : corners) {
    const double e = errorPx(c, T, invert);
    s += std::min(e * e, kCapPx * kCapPx);
  }
  return s;
}

Pose orthonormalised(const Pose& T) {
  Pose out = T;
  out.linear() = Eigen::Quaterniond(T.linear()).normalized().toRotationMatrix();
  return out;
}

// Both IPPE solutions T_cam_tag of a square tag from its ideal normalized corners.
std::vector<Pose> ippe(const TagObservation& o, double size_m) {
  for (bool v : o.valid)
    if (!v) return {};
  const float h = static_cast<float>(0.5 * size_m);
  const std::vector<cv::Point3f> object = {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
  std::vector<cv::Point2f> image;
  for (const auto& p : o.ideal) image.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  std::vector<cv::Mat> rvecs, tvecs;
  try {
    cv::solvePnPGeneric(object, image, cv::Mat::eye(3, 3, CV_64F), cv::Mat(), rvecs, tvecs, false,
                        cv::SOLVEPNP_IPPE_SQUARE);
  } catch (const cv::Exception&) {
    return {};
  }
  std::vector<Pose> out;
  for (size_t i = 0; i < rvecs.size(); ++i) {
    Eigen::Vector3d r, t;
    cv::cv2eigen(rvecs[i], r);
    cv::cv2eigen(tvecs[i], t);
    out.push_back(poseFromRvecTvec(r, t));
  }
  return out;
}

double largestEigen(const Eigen::Matrix3d& m) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(0.5 * (m + m.transpose()));
  return std::max(0.0, es.eigenvalues().maxCoeff());
}

// The shared solve: candidates -> best -> Ceres (robust) -> outliers -> Ceres -> covariance.
PoseEstimate solveCorners(const std::vector<Corner>& all, const std::vector<Pose>& candidates, bool invert,
                          const SolveOptions& options, int tags) {
  PoseEstimate est;
  est.corners = static_cast<int>(all.size());
  est.tags = tags;
  if (all.size() < 4 || candidates.empty()) {
    est.failure = all.size() < 4 ? "fewer than 4 usable corners" : "no initial pose (IPPE failed on every tag)";
    return est;
  }
  std::vector<double> scores(candidates.size());
  size_t best = 0;
  for (size_t i = 0; i < candidates.size(); ++i) {
    scores[i] = score(all, candidates[i], invert);
    if (scores[i] < scores[best]) best = i;
  }
  double rival = kInf;
  for (size_t i = 0; i < candidates.size(); ++i)
    if (rotationDistance(candidates[i], candidates[best]) > radians(10.0)) rival = std::min(rival, scores[i]);
  est.ambiguity_ratio = rival / std::max(scores[best], 1e-12);

  Pose T = orthonormalised(candidates[best]);
  std::vector<Corner> used = all;
  for (int round = 0; round < 2; ++round) {
    const Eigen::Matrix3d R0 = T.linear();
    double w[3] = {0, 0, 0};
    double t[3] = {T.translation().x(), T.translation().y(), T.translation().z()};
    ceres::Problem::Options po;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::HuberLoss loss(options.huber_px);
    ceres::Problem problem(po);
    for (const Corner& c : used)
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<CornerCost, 2, 3, 3>(new CornerCost(c, R0, invert)),
                               &loss, w, t);
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = options.max_iterations;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    est.iterations += static_cast<int>(summary.iterations.size());
    const Eigen::Vector3d wv(w[0], w[1], w[2]);
    const double angle = wv.norm();
    const Eigen::Matrix3d Rw = angle > 0 ? Eigen::AngleAxisd(angle, wv / angle).toRotationMatrix()
                                         : Eigen::Matrix3d::Identity();
    T.linear() = Rw * R0;
    T.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
    T = orthonormalised(T);
    if (round == 1) break;
    std::vector<Corner> kept;
    for (const Corner& c : used)
      if (errorPx(c, T, invert) <= options.outlier_px) kept.push_back(c);
    if (kept.size() == used.size() || kept.size() < 4) break;
    used.swap(kept);
  }

  // Covariance from the Gauss-Newton normal matrix at the solution (no loss weighting), scaled
  // by the corner noise estimated from the inlier residuals (floored).
  const Eigen::Matrix3d R0 = T.linear();
  Eigen::Matrix<double, 6, 6> JtJ = Eigen::Matrix<double, 6, 6>::Zero();
  double sum_sq = 0;
  std::vector<int> cams;
  for (const Corner& c : used) {
    ceres::AutoDiffCostFunction<CornerCost, 2, 3, 3> f(new CornerCost(c, R0, invert));
    double w[3] = {0, 0, 0};
    double t[3] = {T.translation().x(), T.translation().y(), T.translation().z()};
    const double* params[2] = {w, t};
    double r[2] = {0, 0}, jw[6] = {}, jt[6] = {};
    double* jac[2] = {jw, jt};
    f.Evaluate(params, r, jac);
    Eigen::Matrix<double, 2, 6> J;
    for (int i = 0; i < 2; ++i)
      for (int k = 0; k < 3; ++k) {
        J(i, k) = jw[i * 3 + k];
        J(i, 3 + k) = jt[i * 3 + k];
      }
    JtJ += J.transpose() * J;
    sum_sq += r[0] * r[0] + r[1] * r[1];
    cams.push_back(c.camera);
  }
  std::sort(cams.begin(), cams.end());
  cams.erase(std::unique(cams.begin(), cams.end()), cams.end());
  const int n = static_cast<int>(used.size());
  est.inliers = n;
  est.cameras = cams;
  est.rms_px = std::sqrt(sum_sq / std::max(1, n));
  const int dof = 2 * n - 6;
  const double sigma = dof > 0 ? std::sqrt(sum_sq / dof) : est.rms_px;
  est.sigma_px = std::max(sigma, options.min_sigma_px);
  const Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(JtJ);
  if (!lu.isInvertible()) {
    est.failure = "pose not determined by the corners (degenerate geometry)";
    est.T = T;
    return est;
  }
  est.covariance = est.sigma_px * est.sigma_px * lu.inverse();
  est.sigma_rotation_rad = std::sqrt(largestEigen(est.covariance.topLeftCorner<3, 3>()));
  est.sigma_position_m = std::sqrt(largestEigen(est.covariance.bottomRightCorner<3, 3>()));
  est.T = T;
  est.ok = true;
  return est;
}

double meanFocal(const Camera& c) { return std::sqrt(c.fx * c.fy); }

}  // namespace

void SolveOptions::validate() const {
  auto bad = [](const std::string& f, const std::string& what) {
    ErrorContext c;
    c.field = f;
    throw Error("solve: " + what, c);
  };
  if (!(huber_px > 0)) bad("huber_px", "huber_px must be > 0");
  if (!(outlier_px > 0)) bad("outlier_px", "outlier_px must be > 0");
  if (!(min_sigma_px >= 0)) bad("min_sigma_px", "min_sigma_px must be >= 0");
  if (max_iterations < 1) bad("max_iterations", "max_iterations must be >= 1");
}

TagObservation makeTagObservation(const Camera& camera, int camera_index, int tag,
                                  const std::array<Eigen::Vector2d, 4>& corners_px) {
  TagObservation o;
  o.camera = camera_index;
  o.tag = tag;
  o.px = corners_px;
  for (int q = 0; q < 4; ++q) {
    const InverseResult r = camera.undistort(camera.pixelToNormalized(corners_px[q]));
    o.valid[q] = r.ok();
    o.ideal[q] = r.point;
  }
  return o;
}

PoseEstimate solvePropPose(const std::vector<RigCamera>& cameras, const PropDef& prop,
                           const std::vector<TagObservation>& observations, const SolveOptions& options,
                           const Pose* prior) {
  std::vector<Corner> corners;
  std::vector<Pose> candidates;
  if (prior) candidates.push_back(*prior);
  for (const TagObservation& o : observations) {
    if (o.camera < 0 || o.camera >= static_cast<int>(cameras.size()) || o.tag < 0 ||
        o.tag >= static_cast<int>(prop.tags.size()))
      throw Error("solve: observation names camera " + std::to_string(o.camera) + " / tag " +
                  std::to_string(o.tag) + " out of range");
    const RigCamera& rc = cameras[static_cast<size_t>(o.camera)];
    const TagDef& tag = prop.tags[static_cast<size_t>(o.tag)];
    const Pose T_cam_world = rc.T_world_cam.inverse();
    const auto X = tag.cornersInProp();
    for (int q = 0; q < 4; ++q) {
      if (!o.valid[q]) continue;
      Corner c;
      c.camera = o.camera;
      c.X = X[q];
      c.m = o.ideal[q];
      c.f = meanFocal(rc.camera);
      c.RA = T_cam_world.linear();
      c.tA = T_cam_world.translation();
      corners.push_back(c);
    }
    for (const Pose& T_cam_tag : ippe(o, tag.size_m))
      candidates.push_back(rc.T_world_cam * T_cam_tag * tag.T_prop_tag.inverse());
  }
  return solveCorners(corners, candidates, false, options, static_cast<int>(observations.size()));
}

PoseEstimate solveCameraPose(const Camera& camera, const PropDef& tags,
                             const std::vector<TagObservation>& observations, const SolveOptions& options,
                             const Pose* prior) {
  if (!tags.T_world_prop)
    throw Error("track camera: prop " + std::to_string(tags.id) + " ('" + tags.name +
                "') has no T_world_prop: studio tags must say where they are");
  std::vector<Corner> corners;
  std::vector<Pose> candidates;
  if (prior) candidates.push_back(*prior);
  for (const TagObservation& o : observations) {
    if (o.tag < 0 || o.tag >= static_cast<int>(tags.tags.size()))
      throw Error("solve: observation names tag " + std::to_string(o.tag) + " out of range");
    const TagDef& tag = tags.tags[static_cast<size_t>(o.tag)];
    const Pose T_world_tag = *tags.T_world_prop * tag.T_prop_tag;
    const auto X = tag.cornersInProp();
    for (int q = 0; q < 4; ++q) {
      if (!o.valid[q]) continue;
      Corner c;
      c.camera = 0;
      c.X = *tags.T_world_prop * X[q];
      c.m = o.ideal[q];
      c.f = meanFocal(camera);
      corners.push_back(c);
    }
    for (const Pose& T_cam_tag : ippe(o, tag.size_m)) candidates.push_back(T_world_tag * T_cam_tag.inverse());
  }
  return solveCorners(corners, candidates, true, options, static_cast<int>(observations.size()));
}

}  // namespace previz::tracking
