#include "calib/intrinsics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <unordered_map>

#include <ceres/ceres.h>
#include <opencv2/calib3d.hpp>

#include "calib/detail/projection.h"
#include "core/error.h"
#include "core/stopwatch.h"
#include "core/stats.h"

namespace previz::calib {

const std::array<const char*, kIntrinsicCount> kIntrinsicNames = {
    "fx", "fy", "cx", "cy", "skew", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"};
static_assert(kIntrinsicCount == detail::kIntrinsicCount, "calib/intrinsics.h and detail/projection.h disagree");

namespace {

using detail::kCx;
using detail::kCy;
using detail::kFx;
using detail::kFy;
using detail::kK1;
using detail::kK2;
using detail::kK3;
using detail::kK4;
using detail::kK5;
using detail::kK6;
using detail::kP1;
using detail::kP2;
using detail::kSkew;

[[noreturn]] void failField(const std::string& field, const std::string& what) {
  ErrorContext context;
  context.field = field;
  throw Error("calibrate: " + field + " " + what, context);
}

std::string fmt(const char* format, double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), format, v);
  return buffer;
}

struct ReprojectionCost {
  ReprojectionCost(const Eigen::Vector3d& p_board, const Eigen::Vector2d& px, double aspect, LensModel model)
      : p_board_(p_board), px_(px), aspect_(aspect), model_(model) {}

  template <typename T>
  bool operator()(const T* intr, const T* pose, T* residual) const {
    const T p[3] = {T(p_board_.x()), T(p_board_.y()), T(p_board_.z())};
    T uv[2];
    detail::projectBoardPoint(intr, pose, p, aspect_, model_, uv);
    residual[0] = T(px_.x()) - uv[0];
    residual[1] = T(px_.y()) - uv[1];
    return true;
  }

  Eigen::Vector3d p_board_;
  Eigen::Vector2d px_;
  double aspect_;
  LensModel model_;
};

struct PoseOnlyCost {
  PoseOnlyCost(const double* intr, LensModel model, const Eigen::Vector3d& p_board, const Eigen::Vector2d& px)
      : model_(model), p_board_(p_board), px_(px) {
    std::copy(intr, intr + kIntrinsicCount, intr_);
  }
  template <typename T>
  bool operator()(const T* pose, T* residual) const {
    T intr[kIntrinsicCount];
    for (int i = 0; i < kIntrinsicCount; ++i) intr[i] = T(intr_[i]);
    const T p[3] = {T(p_board_.x()), T(p_board_.y()), T(p_board_.z())};
    T uv[2];
    detail::projectBoardPoint(intr, pose, p, 0.0, model_, uv);
    residual[0] = T(px_.x()) - uv[0];
    residual[1] = T(px_.y()) - uv[1];
    return true;
  }
  double intr_[kIntrinsicCount];
  LensModel model_;
  Eigen::Vector3d p_board_;
  Eigen::Vector2d px_;
};

Pose arrayToPose(const std::array<double, 6>& a) {
  return poseFromRvecTvec(Eigen::Vector3d(a[0], a[1], a[2]), Eigen::Vector3d(a[3], a[4], a[5]));
}

// One usable point of one view.
struct SolvePoint {
  int view;
  int id;
  Eigen::Vector3d p_board;
  Eigen::Vector2d px;
  bool active = true;
  ceres::ResidualBlockId block = nullptr;
};

Eigen::Vector2d residualAt(const double* intr, const std::array<double, 6>& pose,
                           const SolvePoint& p, double aspect, LensModel model) {
  double uv[2];
  detail::projectBoardPoint(intr, pose.data(), p.p_board.data(), aspect, model, uv);
  return p.px - Eigen::Vector2d(uv[0], uv[1]);
}

// The board points of a view, in a form the solve takes; why not, when it cannot.
struct ViewPoints {
  std::vector<int> ids;
  std::vector<Eigen::Vector3d> p_board;
  std::vector<Eigen::Vector2d> px;
};

std::string usableViewPoints(const ViewObservations& view,
                             const std::unordered_map<int, Eigen::Vector3d>& board_points,
                             int min_points, ViewPoints& out) {
  if (!view.found()) return view.failure.empty() ? "no board found" : view.failure;
  if (view.rejected) return view.rejected_reason.empty() ? "rejected" : view.rejected_reason;
  std::vector<bool> seen;
  for (const Observation& o : view.points) {
    auto it = board_points.find(o.id);
    if (it == board_points.end()) return "point id " + std::to_string(o.id) + " is not on the board";
    if (!o.px.allFinite()) continue;
    if (std::find(out.ids.begin(), out.ids.end(), o.id) != out.ids.end()) continue;  // duplicate
    out.ids.push_back(o.id);
    out.p_board.push_back(it->second);
    out.px.push_back(o.px);
  }
  if (static_cast<int>(out.ids.size()) < min_points) {
    return "only " + std::to_string(out.ids.size()) + " points (need " +
           std::to_string(min_points) + ")";
  }
  // A pose (and a homography for OpenCV's initialisation) needs points spread over the plane.
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : out.p_board) mean += p.head<2>();
  mean /= out.p_board.size();
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const auto& p : out.p_board) cov += (p.head<2>() - mean) * (p.head<2>() - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  if (!(eig.eigenvalues()(0) > 1e-4 * eig.eigenvalues()(1))) return "points (nearly) collinear";
  return {};
}

std::unordered_map<int, Eigen::Vector3d> boardPointMap(const BoardSpec& board) {
  std::unordered_map<int, Eigen::Vector3d> m;
  for (const BoardPoint& p : boardPoints(board)) m[p.id] = p.p_board;
  return m;
}

// refine: polish through previz's model (skew included); the bundle adjustment does it anyway
// for the poses it starts from.
std::optional<std::array<double, 6>> pnp(const double* intr, LensModel model, const ViewPoints& vp, bool refine) {
  if (vp.ids.size() < 4) return std::nullopt;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  cv::Matx33d K(intr[kFx], intr[kSkew], intr[kCx], 0, intr[kFy], intr[kCy], 0, 0, 1);
  cv::Vec<double, 8> dist(intr[kK1], intr[kK2], intr[kP1], intr[kP2], intr[kK3], intr[kK4], intr[kK5], intr[kK6]);
  // OpenCV's solvePnP knows Brown-Conrady only. Another lens's points are turned into rays and
  // seen by a virtual pinhole looking along their mean (R_virtual_cam): a board across a wide
  // angle is then near that pinhole's axis, where normalized coordinates stay finite.
  Eigen::Matrix3d R_virtual_cam = Eigen::Matrix3d::Identity();
  if (model == LensModel::kBrownConrady) {
    for (size_t i = 0; i < vp.ids.size(); ++i) {
      image.emplace_back(vp.px[i].x(), vp.px[i].y());
      object.emplace_back(vp.p_board[i].x(), vp.p_board[i].y(), vp.p_board[i].z());
    }
  } else {
    Camera camera;
    detail::vectorToCamera(intr, model, camera);
    std::vector<Eigen::Vector3d> rays;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < vp.ids.size(); ++i) {
      const auto ray = camera.unproject(vp.px[i]);
      if (!ray) continue;
      rays.push_back(*ray);
      mean += *ray;
      object.emplace_back(vp.p_board[i].x(), vp.p_board[i].y(), vp.p_board[i].z());
    }
    if (rays.size() < 4 || !(mean.norm() > 0)) return std::nullopt;
    R_virtual_cam = Eigen::Quaterniond::FromTwoVectors(mean.normalized(), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    for (const Eigen::Vector3d& ray : rays) {
      const Eigen::Vector3d q = R_virtual_cam * ray;
      if (!(q.z() > 1e-3)) return std::nullopt;  // the board spans 180 degrees of the virtual view
      image.emplace_back(q.x() / q.z(), q.y() / q.z());
    }
    K = cv::Matx33d::eye();
    dist = cv::Vec<double, 8>::all(0.0);
  }
  cv::Vec3d rvec, tvec;
  bool ok = false;
  try {
    ok = cv::solvePnP(object, image, K, dist, rvec, tvec, false, cv::SOLVEPNP_IPPE);
    if (!ok) ok = cv::solvePnP(object, image, K, dist, rvec, tvec, false, cv::SOLVEPNP_ITERATIVE);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok || !(tvec[2] > 0)) return std::nullopt;
  if (model != LensModel::kBrownConrady) {
    // T_cam_board = R_virtual_cam^T T_virtual_board.
    Pose T_cam_virtual = Pose::Identity();
    T_cam_virtual.linear() = R_virtual_cam.transpose();
    const Pose T = T_cam_virtual * poseFromRvecTvec(Eigen::Vector3d(rvec[0], rvec[1], rvec[2]),
                                                    Eigen::Vector3d(tvec[0], tvec[1], tvec[2]));
    Eigen::Vector3d r, t;
    poseToRvecTvec(T, r, t);
    rvec = cv::Vec3d(r.x(), r.y(), r.z());
    tvec = cv::Vec3d(t.x(), t.y(), t.z());
  }
  std::array<double, 6> pose = {rvec[0], rvec[1], rvec[2], tvec[0], tvec[1], tvec[2]};
  if (!refine) return pose;
  ceres::Problem problem;
  for (size_t i = 0; i < vp.ids.size(); ++i) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PoseOnlyCost, 2, 6>(
                                 new PoseOnlyCost(intr, model, vp.p_board[i], vp.px[i])),
                             nullptr, pose.data());
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 50;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (!summary.IsSolutionUsable()) return std::nullopt;
  return pose;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Locks and options

IntrinsicLocks IntrinsicLocks::parse(const std::string& list) {
  IntrinsicLocks locks;
  std::stringstream stream(list);
  std::string name;
  while (std::getline(stream, name, ',')) {
    name.erase(0, name.find_first_not_of(" \t"));
    name.erase(name.find_last_not_of(" \t") + 1);
    if (name.empty()) continue;
    if (name == "fix_focal") locks.fix_focal = true;
    else if (name == "fix_aspect") locks.fix_aspect = true;
    else if (name == "fix_principal_point") locks.fix_principal_point = true;
    else if (name == "fix_skew") locks.fix_skew = true;
    else if (name == "free_skew") locks.fix_skew = false;
    else if (name == "fix_k1") locks.fix_k1 = true;
    else if (name == "fix_k2") locks.fix_k2 = true;
    else if (name == "fix_k3") locks.fix_k3 = true;
    else if (name == "fix_k4") locks.fix_k4 = true;
    else if (name == "fix_k5") locks.fix_k5 = true;
    else if (name == "fix_k6") locks.fix_k6 = true;
    else if (name == "rational") locks.rational = true;
    else if (name == "fix_tangential") locks.fix_tangential = true;
    else if (name == "fix_radial")
      locks.fix_k1 = locks.fix_k2 = locks.fix_k3 = locks.fix_k4 = locks.fix_k5 = locks.fix_k6 = true;
    else if (name == "fix_distortion")
      locks.fix_k1 = locks.fix_k2 = locks.fix_k3 = locks.fix_k4 = locks.fix_k5 = locks.fix_k6 =
          locks.fix_tangential = true;
    else {
      ErrorContext context;
      context.field = "lock";
      throw Error("calibrate: unknown lock '" + name +
                      "' (known: fix_focal, fix_aspect, fix_principal_point, fix_skew, free_skew, "
                      "fix_k1, fix_k2, fix_k3, fix_k4, fix_k5, fix_k6, fix_tangential, fix_radial, fix_distortion, "
                      "rational)",
                  context);
    }
  }
  return locks;
}

std::string IntrinsicLocks::toString() const {
  std::vector<std::string> names;
  if (fix_focal) names.push_back("fix_focal");
  if (fix_aspect) names.push_back("fix_aspect");
  if (fix_principal_point) names.push_back("fix_principal_point");
  if (!fix_skew) names.push_back("free_skew");
  if (fix_k1) names.push_back("fix_k1");
  if (fix_k2) names.push_back("fix_k2");
  if (fix_k3) names.push_back("fix_k3");
  if (fix_k4) names.push_back("fix_k4");
  if (fix_k5) names.push_back("fix_k5");
  if (fix_k6) names.push_back("fix_k6");
  if (fix_tangential) names.push_back("fix_tangential");
  if (rational) names.push_back("rational");
  std::string out;
  for (const auto& n : names) out += (out.empty() ? "" : ",") + n;
  return out;
}

std::array<bool, kIntrinsicCount> IntrinsicLocks::heldMask(LensModel model) const {
  std::array<bool, kIntrinsicCount> m{};
  m[kFx] = fix_focal;
  m[kFy] = fix_focal || fix_aspect;
  m[kCx] = m[kCy] = fix_principal_point;
  m[kSkew] = fix_skew;
  m[kK1] = fix_k1;
  m[kK2] = fix_k2;
  m[kK3] = fix_k3;
  m[kK4] = fix_k4;
  m[kK5] = fix_k5;
  m[kK6] = fix_k6;
  m[kP1] = m[kP2] = fix_tangential;
  if (model == LensModel::kKannalaBrandt) m[kP1] = m[kP2] = m[kK5] = m[kK6] = true;
  else if (!rational) m[kK4] = m[kK5] = m[kK6] = true;
  return m;
}

const char* toString(RobustLoss loss) {
  switch (loss) {
    case RobustLoss::kNone: return "none";
    case RobustLoss::kHuber: return "huber";
    case RobustLoss::kCauchy: return "cauchy";
  }
  return "?";
}

RobustLoss robustLossFromString(const std::string& name) {
  if (name == "none") return RobustLoss::kNone;
  if (name == "huber") return RobustLoss::kHuber;
  if (name == "cauchy") return RobustLoss::kCauchy;
  ErrorContext context;
  context.field = "loss";
  throw Error("calibrate: unknown robust loss '" + name + "' (none, huber, cauchy)", context);
}

void IntrinsicsOptions::validate() const {
  if (!(loss_scale_px > 0) || !std::isfinite(loss_scale_px))
    failField("loss_scale_px", "must be > 0 (got " + std::to_string(loss_scale_px) + ")");
  if (!(outlier_sigma > 1) || !std::isfinite(outlier_sigma))
    failField("outlier_sigma", "must be > 1 (got " + std::to_string(outlier_sigma) + ")");
  if (max_rejection_rounds < 0)
    failField("max_rejection_rounds", "must be >= 0 (got " + std::to_string(max_rejection_rounds) + ")");
  if (min_points_per_view < 4)
    failField("min_points_per_view", "must be >= 4 (got " + std::to_string(min_points_per_view) + ")");
  if (min_views < 2) failField("min_views", "must be >= 2 (got " + std::to_string(min_views) + ")");
  if (max_iterations < 1)
    failField("max_iterations", "must be >= 1 (got " + std::to_string(max_iterations) + ")");
  if (threads < 1) failField("threads", "must be >= 1 (got " + std::to_string(threads) + ")");
  if (locks.fix_focal && !initial_camera)
    failField("initial_camera", "is needed by the fix_focal lock (the focal length to hold)");
  if (!opencv_init && !initial_camera)
    failField("initial_camera", "is needed when opencv_init is false");
  if (initial_camera) {
    initial_camera->validate();
    if (initial_camera->dist.model != model)
      failField("initial_camera", std::string("lens model is ") + previz::toString(initial_camera->dist.model) +
                                      " but the solve is for " + previz::toString(model));
  }
}

// ---------------------------------------------------------------------------------------------

namespace {

// The starting point of a Kannala–Brandt solve: OpenCV's fisheye calibration (its own
// initialisation, a few iterations), with the locks it has.
void initFisheye(const std::vector<ViewPoints>& used_points, const cv::Size& size, const Camera& lock_values,
                 const IntrinsicsOptions& options, double& initial_rms_px, double* intr,
                 std::vector<std::array<double, 6>>& poses) {
  std::vector<std::vector<cv::Point3d>> object(used_points.size());
  std::vector<std::vector<cv::Point2d>> image(used_points.size());
  for (size_t k = 0; k < used_points.size(); ++k) {
    for (size_t i = 0; i < used_points[k].ids.size(); ++i) {
      const Eigen::Vector3d& p = used_points[k].p_board[i];
      object[k].emplace_back(p.x(), p.y(), p.z());
      image[k].emplace_back(used_points[k].px[i].x(), used_points[k].px[i].y());
    }
  }
  int flags = cv::fisheye::CALIB_RECOMPUTE_EXTRINSIC | cv::fisheye::CALIB_FIX_SKEW;
  if (options.initial_camera) flags |= cv::fisheye::CALIB_USE_INTRINSIC_GUESS;
  if (options.locks.fix_focal) flags |= cv::fisheye::CALIB_FIX_FOCAL_LENGTH;
  if (options.locks.fix_principal_point) flags |= cv::fisheye::CALIB_FIX_PRINCIPAL_POINT;
  if (options.locks.fix_k1) flags |= cv::fisheye::CALIB_FIX_K1;
  if (options.locks.fix_k2) flags |= cv::fisheye::CALIB_FIX_K2;
  if (options.locks.fix_k3) flags |= cv::fisheye::CALIB_FIX_K3;
  if (options.locks.fix_k4) flags |= cv::fisheye::CALIB_FIX_K4;
  cv::Matx33d K(lock_values.fx, 0, lock_values.cx, 0, lock_values.fy, lock_values.cy, 0, 0, 1);
  cv::Vec4d D(lock_values.dist.k1, lock_values.dist.k2, lock_values.dist.k3, lock_values.dist.k4);
  std::vector<cv::Vec3d> rvecs, tvecs;
  try {
    initial_rms_px = cv::fisheye::calibrate(object, image, size, K, D, rvecs, tvecs, flags,
                                            cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 1e-10));
  } catch (const cv::Exception& e) {
    throw Error(std::string("calibrate: OpenCV's fisheye::calibrate (initialisation of the kannala-brandt solve) "
                            "failed: ") +
                e.what());
  }
  Camera init = lock_values;
  init.fx = K(0, 0);
  init.fy = K(1, 1);
  init.cx = K(0, 2);
  init.cy = K(1, 2);
  init.skew = 0;
  init.dist = Distortion::kannalaBrandt(D[0], D[1], D[2], D[3]);
  detail::cameraToVector(init, intr);
  for (size_t k = 0; k < used_points.size(); ++k)
    poses[k] = {rvecs[k][0], rvecs[k][1], rvecs[k][2], tvecs[k][0], tvecs[k][1], tvecs[k][2]};
}

}  // namespace

std::optional<Pose> estimateBoardPose(const Camera& camera, const ViewObservations& view,
                                      const BoardSpec& board, bool refine) {
  ViewPoints vp;
  if (!usableViewPoints(view, boardPointMap(board), 4, vp).empty()) return std::nullopt;
  double intr[kIntrinsicCount];
  detail::cameraToVector(camera, intr);
  const auto pose = pnp(intr, camera.dist.model, vp, refine);
  if (!pose) return std::nullopt;
  return arrayToPose(*pose);
}

IntrinsicsResult calibrateIntrinsics(const std::vector<ViewObservations>& views,
                                     const BoardSpec& board, const IntrinsicsOptions& options) {
  const Stopwatch solve_time;
  options.validate();
  board.validate();
  const auto board_points = boardPointMap(board);

  IntrinsicsResult result;
  result.locks = options.locks;
  result.views.resize(views.size());

  // Usable views and the image size they share.
  std::vector<int> used;                 // input indices of the views in the solve
  std::vector<ViewPoints> used_points;
  for (size_t v = 0; v < views.size(); ++v) {
    ViewResult& vr = result.views[v];
    vr.source = views[v].source.empty() ? "view " + std::to_string(v) : views[v].source;
    vr.points = static_cast<int>(views[v].points.size());
    ViewPoints vp;
    vr.dropped_reason = usableViewPoints(views[v], board_points, options.min_points_per_view, vp);
    if (!vr.dropped_reason.empty()) continue;
    if (views[v].image_size.width <= 0 || views[v].image_size.height <= 0) {
      ErrorContext context;
      context.file = vr.source;
      throw Error("calibrate: view has no image size", context);
    }
    if (result.image_size.width == 0) {
      result.image_size = views[v].image_size;
    } else if (views[v].image_size != result.image_size) {
      ErrorContext context;
      context.file = vr.source;
      throw Error("calibrate: image size " + std::to_string(views[v].image_size.width) + "x" +
                      std::to_string(views[v].image_size.height) + " differs from the first view's " +
                      std::to_string(result.image_size.width) + "x" +
                      std::to_string(result.image_size.height),
                  context);
    }
    used.push_back(static_cast<int>(v));
    used_points.push_back(std::move(vp));
  }
  if (static_cast<int>(used.size()) < options.min_views) {
    throw Error("calibrate: only " + std::to_string(used.size()) + " of " +
                std::to_string(views.size()) + " views show a usable board (need " +
                std::to_string(options.min_views) + ")");
  }
  if (options.initial_camera &&
      (options.initial_camera->width != result.image_size.width ||
       options.initial_camera->height != result.image_size.height)) {
    failField("initial_camera", "size differs from the images'");
  }
  const int w = result.image_size.width, h = result.image_size.height;

  // Values the held parameters keep.
  const LensModel model = options.model;
  Camera lock_values;
  lock_values.dist.model = model;
  if (options.initial_camera) {
    lock_values = *options.initial_camera;
  } else {
    lock_values.width = w;
    lock_values.height = h;
    lock_values.fx = lock_values.fy = std::max(w, h);
    lock_values.cx = 0.5 * (w - 1);
    lock_values.cy = 0.5 * (h - 1);
  }
  const std::array<bool, kIntrinsicCount> held = options.locks.heldMask(model);
  const double aspect_lock = lock_values.fy / lock_values.fx;
  const double tie_aspect = options.locks.fix_aspect ? aspect_lock : 0.0;

  // ---- initialisation
  double intr[kIntrinsicCount];
  std::vector<std::array<double, 6>> poses(used.size());
  if (options.opencv_init && model == LensModel::kKannalaBrandt) {
    initFisheye(used_points, result.image_size, lock_values, options, result.initial_rms_px, intr, poses);
  } else if (options.opencv_init) {
    std::vector<std::vector<cv::Point3f>> object(used.size());
    std::vector<std::vector<cv::Point2f>> image(used.size());
    for (size_t k = 0; k < used.size(); ++k) {
      for (size_t i = 0; i < used_points[k].ids.size(); ++i) {
        const auto& p = used_points[k].p_board[i];
        object[k].emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()),
                               static_cast<float>(p.z()));
        image[k].emplace_back(static_cast<float>(used_points[k].px[i].x()),
                              static_cast<float>(used_points[k].px[i].y()));
      }
    }
    int flags = 0;
    cv::Matx33d K(lock_values.fx, 0, lock_values.cx, 0, lock_values.fy, lock_values.cy, 0, 0, 1);
    // OpenCV's rational model when k4 k5 k6 are solved, or held at non-zero values; held ones
    // are CALIB_FIX_K4..6 (OpenCV fixes them at the guess it is given).
    const bool rational = options.locks.rational || lock_values.dist.isRational();
    cv::Mat dist = (cv::Mat_<double>(1, 8) << lock_values.dist.k1, lock_values.dist.k2, lock_values.dist.p1,
                    lock_values.dist.p2, lock_values.dist.k3, lock_values.dist.k4, lock_values.dist.k5,
                    lock_values.dist.k6);
    if (!rational) dist = dist.colRange(0, 5).clone();
    if (rational) {
      flags |= cv::CALIB_RATIONAL_MODEL;
      if (held[kK4]) flags |= cv::CALIB_FIX_K4;
      if (held[kK5]) flags |= cv::CALIB_FIX_K5;
      if (held[kK6]) flags |= cv::CALIB_FIX_K6;
    }
    if (options.initial_camera) flags |= cv::CALIB_USE_INTRINSIC_GUESS;
    if (options.locks.fix_focal) flags |= cv::CALIB_FIX_FOCAL_LENGTH;
    if (options.locks.fix_aspect) flags |= cv::CALIB_FIX_ASPECT_RATIO;
    if (options.locks.fix_principal_point) flags |= cv::CALIB_FIX_PRINCIPAL_POINT;
    if (options.locks.fix_k1) flags |= cv::CALIB_FIX_K1;
    if (options.locks.fix_k2) flags |= cv::CALIB_FIX_K2;
    if (options.locks.fix_k3) flags |= cv::CALIB_FIX_K3;
    if (options.locks.fix_tangential) {
      flags |= (lock_values.dist.p1 == 0 && lock_values.dist.p2 == 0) ? cv::CALIB_ZERO_TANGENT_DIST
                                                                      : cv::CALIB_FIX_TANGENT_DIST;
    }
    std::vector<cv::Mat> rvecs, tvecs;
    cv::Mat K_mat(K);
    try {
      // Only a starting point for the Ceres solve: LU and a few iterations cost a fraction of
      // OpenCV's defaults (30 iterations, SVD) and land in the same basin.
      result.initial_rms_px = cv::calibrateCamera(
          object, image, result.image_size, K_mat, dist, rvecs, tvecs, flags | cv::CALIB_USE_LU,
          cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 10, 1e-9));
    } catch (const cv::Exception& e) {
      throw Error(std::string("calibrate: OpenCV's calibrateCamera (initialisation) failed: ") +
                  e.what());
    }
    Camera init = lock_values;
    init.fx = K_mat.at<double>(0, 0);
    init.fy = K_mat.at<double>(1, 1);
    init.cx = K_mat.at<double>(0, 2);
    init.cy = K_mat.at<double>(1, 2);
    init.skew = 0;
    init.dist.k1 = dist.at<double>(0);
    init.dist.k2 = dist.at<double>(1);
    init.dist.p1 = dist.at<double>(2);
    init.dist.p2 = dist.at<double>(3);
    init.dist.k3 = dist.at<double>(4);
    if (rational) {
      init.dist.k4 = dist.at<double>(5);
      init.dist.k5 = dist.at<double>(6);
      init.dist.k6 = dist.at<double>(7);
    }
    detail::cameraToVector(init, intr);
    for (size_t k = 0; k < used.size(); ++k) {
      const cv::Vec3d r(rvecs[k]), t(tvecs[k]);
      poses[k] = {r[0], r[1], r[2], t[0], t[1], t[2]};
    }
  } else {
    detail::cameraToVector(*options.initial_camera, intr);
  }
  // Held parameters take their lock values exactly (OpenCV's own fixed values may differ, e.g.
  // its image centre convention).
  {
    double lock_vec[kIntrinsicCount];
    detail::cameraToVector(lock_values, lock_vec);
    for (int i = 0; i < kIntrinsicCount; ++i)
      if (held[i] && !(i == kFy && options.locks.fix_aspect && !options.locks.fix_focal))
        intr[i] = lock_vec[i];
    if (options.locks.fix_aspect) intr[kFy] = aspect_lock * intr[kFx];
  }
  if (!options.opencv_init) {
    for (size_t k = 0; k < used.size(); ++k) {
      const auto pose = pnp(intr, model, used_points[k], false);
      if (!pose) {
        ErrorContext context;
        context.file = result.views[used[k]].source;
        throw Error("calibrate: board pose could not be found from the initial camera", context);
      }
      poses[k] = *pose;
    }
  }
  detail::vectorToCamera(intr, model, result.initial_camera);
  result.initial_camera.name = options.camera_name;
  result.initial_camera.width = w;
  result.initial_camera.height = h;

  // ---- the problem
  std::vector<SolvePoint> points;
  for (size_t k = 0; k < used.size(); ++k) {
    for (size_t i = 0; i < used_points[k].ids.size(); ++i) {
      SolvePoint p;
      p.view = static_cast<int>(k);
      p.id = used_points[k].ids[i];
      p.p_board = used_points[k].p_board[i];
      p.px = used_points[k].px[i];
      points.push_back(p);
    }
  }
  if (!options.opencv_init) {
    double ssr = 0;
    for (const SolvePoint& p : points) ssr += residualAt(intr, poses[p.view], p, tie_aspect, model).squaredNorm();
    result.initial_rms_px = std::sqrt(ssr / points.size());
  }

  ceres::Problem::Options problem_options;
  problem_options.enable_fast_removal = true;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  std::unique_ptr<ceres::LossFunction> loss;
  if (options.loss == RobustLoss::kHuber) loss = std::make_unique<ceres::HuberLoss>(options.loss_scale_px);
  if (options.loss == RobustLoss::kCauchy) loss = std::make_unique<ceres::CauchyLoss>(options.loss_scale_px);
  for (SolvePoint& p : points) {
    p.block = problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<ReprojectionCost, 2, kIntrinsicCount, 6>(
            new ReprojectionCost(p.p_board, p.px, tie_aspect, model)),
        loss.get(), intr, poses[p.view].data());
  }
  std::vector<int> constant;
  for (int i = 0; i < kIntrinsicCount; ++i)
    if (held[i]) constant.push_back(i);
  if (static_cast<int>(constant.size()) == kIntrinsicCount) {
    problem.SetParameterBlockConstant(intr);
  } else if (!constant.empty()) {
    problem.SetManifold(intr, new ceres::SubsetManifold(kIntrinsicCount, constant));
  }
  const int free_intrinsics = kIntrinsicCount - static_cast<int>(constant.size());

  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_SCHUR;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = 1e-12;
  solver_options.gradient_tolerance = 1e-14;
  solver_options.parameter_tolerance = 1e-12;
  solver_options.num_threads = options.threads;

  std::vector<bool> view_active(used.size(), true);
  for (int round = 0;; ++round) {
    ceres::Solver::Summary summary;
    ceres::Solve(solver_options, &problem, &summary);
    result.iterations += static_cast<int>(summary.iterations.size());
    result.termination = summary.message;
    if (!summary.IsSolutionUsable()) {
      throw Error("calibrate: the solve failed: " + summary.message);
    }
    if (!options.reject_outliers || round >= options.max_rejection_rounds) break;
    std::vector<double> norms;
    for (const SolvePoint& p : points)
      if (p.active) norms.push_back(residualAt(intr, poses[p.view], p, tie_aspect, model).norm());
    const double threshold = options.outlier_sigma * median(norms) / 1.1774;
    int rejected = 0;
    std::vector<int> remaining(used.size(), 0);
    for (SolvePoint& p : points) {
      if (!p.active) continue;
      if (residualAt(intr, poses[p.view], p, tie_aspect, model).norm() > threshold) {
        p.active = false;
        problem.RemoveResidualBlock(p.block);
        p.block = nullptr;
        ++rejected;
      } else {
        ++remaining[p.view];
      }
    }
    if (rejected == 0) break;
    ++result.rejection_rounds;
    for (size_t k = 0; k < used.size(); ++k) {
      if (view_active[k] && remaining[k] < options.min_points_per_view) {
        view_active[k] = false;
        for (SolvePoint& p : points) {
          if (p.view == static_cast<int>(k) && p.active) {
            p.active = false;
            problem.RemoveResidualBlock(p.block);
            p.block = nullptr;
          }
        }
        problem.RemoveParameterBlock(poses[k].data());
        result.views[used[k]].dropped_reason =
            "only " + std::to_string(remaining[k]) + " points left after outlier rejection";
      }
    }
    if (std::count(view_active.begin(), view_active.end(), true) < options.min_views) {
      throw Error("calibrate: outlier rejection left fewer than " +
                  std::to_string(options.min_views) + " views");
    }
  }

  // ---- results
  detail::vectorToCamera(intr, model, result.camera);
  if (options.locks.fix_aspect) result.camera.fy = tie_aspect * result.camera.fx;
  result.camera.name = options.camera_name;
  result.camera.width = w;
  result.camera.height = h;

  double ssr_active = 0, ssr_all = 0;
  int n_active = 0;
  std::vector<double> view_ssr(used.size(), 0.0);
  for (const SolvePoint& p : points) {
    const int v = used[p.view];
    ViewResult& vr = result.views[v];
    if (!view_active[p.view]) continue;
    const Eigen::Vector2d r = residualAt(intr, poses[p.view], p, tie_aspect, model);
    PointResidual pr;
    pr.view = v;
    pr.id = p.id;
    pr.px = p.px;
    pr.residual = r;
    pr.rejected = !p.active;
    result.residuals.push_back(pr);
    ssr_all += r.squaredNorm();
    if (p.active) {
      ssr_active += r.squaredNorm();
      ++n_active;
      view_ssr[p.view] += r.squaredNorm();
      ++vr.points_used;
      vr.max_px = std::max(vr.max_px, r.norm());
    } else {
      ++vr.points_rejected;
    }
  }
  for (size_t k = 0; k < used.size(); ++k) {
    ViewResult& vr = result.views[used[k]];
    if (!view_active[k]) continue;
    vr.used = true;
    vr.T_cam_board = arrayToPose(poses[k]);
    vr.rms_px = vr.points_used > 0 ? std::sqrt(view_ssr[k] / vr.points_used) : 0.0;
    ++result.views_used;
    result.points_total += vr.points_used + vr.points_rejected;
    result.points_rejected += vr.points_rejected;
  }
  result.points_used = n_active;
  result.rms_px = n_active > 0 ? std::sqrt(ssr_active / n_active) : 0.0;
  result.rms_all_px = result.points_total > 0 ? std::sqrt(ssr_all / result.points_total) : 0.0;
  result.free_parameters = free_intrinsics + 6 * result.views_used;
  const int dof = 2 * n_active - result.free_parameters;
  result.residual_sigma_px = dof > 0 ? std::sqrt(ssr_active / dof) : 0.0;

  // ---- covariance: ceres::Covariance treats residuals as unit-variance, so scale by the
  // estimated noise variance (Hartley & Zisserman 5.2).
  result.covariance = Eigen::MatrixXd::Zero(kIntrinsicCount, kIntrinsicCount);
  if (options.compute_covariance && dof > 0) {
    std::vector<const double*> blocks = {intr};
    if (options.joint_covariance) {
      for (size_t k = 0; k < used.size(); ++k) {
        if (!view_active[k]) continue;
        blocks.push_back(poses[k].data());
        result.joint_views.push_back(used[k]);
      }
    }
    const bool all_held = free_intrinsics == 0;
    bool ok = false;
    Eigen::MatrixXd joint;
    const int n = kIntrinsicCount + 6 * (static_cast<int>(blocks.size()) - 1);
    for (const auto algorithm : {ceres::SPARSE_QR, ceres::DENSE_SVD}) {
      ceres::Covariance::Options co;
      co.algorithm_type = algorithm;
      co.num_threads = options.threads;
      co.apply_loss_function = true;
      ceres::Covariance covariance(co);
      std::vector<const double*> compute_blocks = blocks;
      if (all_held) compute_blocks.erase(compute_blocks.begin());
      if (compute_blocks.empty()) break;
      if (!covariance.Compute(compute_blocks, &problem)) continue;
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> m(n, n);
      m.setZero();
      if (all_held) {
        Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> sub(n - kIntrinsicCount,
                                                                                   n - kIntrinsicCount);
        if (!covariance.GetCovarianceMatrix(compute_blocks, sub.data())) continue;
        m.bottomRightCorner(n - kIntrinsicCount, n - kIntrinsicCount) = sub;
      } else if (!covariance.GetCovarianceMatrix(compute_blocks, m.data())) {
        continue;
      }
      joint = m;
      ok = true;
      break;
    }
    if (ok) {
      joint *= result.residual_sigma_px * result.residual_sigma_px;
      if (options.locks.fix_aspect && !options.locks.fix_focal) {
        // fy = aspect * fx: its row and column follow fx's.
        joint.row(kFy) = tie_aspect * joint.row(kFx);
        joint.col(kFy) = tie_aspect * joint.col(kFx);
      }
      result.covariance = joint.topLeftCorner(kIntrinsicCount, kIntrinsicCount);
      if (options.joint_covariance) result.joint_covariance = joint;
      for (int i = 0; i < kIntrinsicCount; ++i)
        result.sigma[i] = std::sqrt(std::max(0.0, result.covariance(i, i)));
      result.covariance_ok = true;
    } else {
      result.covariance_message =
          "the Jacobian is rank deficient (a parameter is not observable from these views)";
      result.joint_views.clear();
    }
  } else if (options.compute_covariance) {
    result.covariance_message = "not enough points for the number of parameters";
  }
  result.solve_ms = solve_time.ms();
  return result;
}

// ---------------------------------------------------------------------------------------------
// Reports

std::string IntrinsicsResult::briefReport() const {
  std::ostringstream s;
  s << "calib: " << views_used << "/" << views.size() << " views, " << points_used << " points ("
    << points_rejected << " rejected), RMS " << fmt("%.4f", rms_px) << " px, fx "
    << fmt("%.3f", camera.fx) << " +- " << fmt("%.3f", sigma[kFx]) << ", cx "
    << fmt("%.3f", camera.cx) << " +- " << fmt("%.3f", sigma[kCx]) << ", k1 "
    << fmt("%.5f", camera.dist.k1) << " +- " << fmt("%.5f", sigma[kK1]);
  return s.str();
}

std::string IntrinsicsResult::fullReport() const {
  std::ostringstream s;
  char line[256];
  s << "previz intrinsic calibration\n";
  s << "  image                " << image_size.width << " x " << image_size.height << " px\n";
  s << "  views                " << views.size() << " given, " << views_used << " used\n";
  s << "  points               " << points_total << " in used views, " << points_used << " used, "
    << points_rejected << " rejected as outliers (" << rejection_rounds << " re-solves)\n";
  s << "  locks                " << (locks.toString().empty() ? "none" : locks.toString()) << "\n";
  s << "  free parameters      " << free_parameters << " (intrinsics + 6 per view)\n";
  std::snprintf(line, sizeof(line), "  RMS                  %.4f px (all points %.4f px, start %.4f px)\n",
                rms_px, rms_all_px, initial_rms_px);
  s << line;
  std::snprintf(line, sizeof(line), "  noise estimate       %.4f px per coordinate\n", residual_sigma_px);
  s << line;
  s << "  covariance           "
    << (covariance_ok ? "ok (sigmas scaled by the noise estimate)" : "unavailable: " + covariance_message)
    << "\n\n";
  const LensModel model = camera.dist.model;
  const std::array<bool, kIntrinsicCount> held = locks.heldMask(model);
  double start_v[kIntrinsicCount], est_v[kIntrinsicCount];
  detail::cameraToVector(initial_camera, start_v);
  detail::cameraToVector(camera, est_v);
  s << "  lens model           " << previz::toString(model) << "\n";
  s << "  parameter        start         estimate        sigma\n";
  for (int i = 0; i < kIntrinsicCount; ++i) {
    // Terms the lens model does not have are not listed, nor Brown's rational terms when they
    // were not solved and are 0.
    if (model == LensModel::kKannalaBrandt && (i == kP1 || i == kP2 || i == kK5 || i == kK6)) continue;
    if (model == LensModel::kBrownConrady && i >= kK4 && held[i] && est_v[i] == 0.0) continue;
    const bool is_distortion = i >= kK1;
    std::snprintf(line, sizeof(line),
                  is_distortion ? "  %-6s %15.7f %15.7f %12.7f%s\n" : "  %-6s %15.4f %15.4f %12.4f%s\n",
                  kIntrinsicNames[i], start_v[i], est_v[i], sigma[i],
                  held[i] ? (i == kFy && locks.fix_aspect && !locks.fix_focal ? "  (fy/fx held)" : "  (held)")
                          : "");
    s << line;
  }
  s << "\n   #  view                              points  used  rej    RMS px   max px\n";
  for (size_t v = 0; v < views.size(); ++v) {
    const ViewResult& vr = views[v];
    std::string name = vr.source;
    if (name.size() > 32) name = "..." + name.substr(name.size() - 29);
    if (vr.used) {
      std::snprintf(line, sizeof(line), "  %2zu  %-32s %6d %5d %4d %9.4f %8.4f\n", v, name.c_str(),
                    vr.points, vr.points_used, vr.points_rejected, vr.rms_px, vr.max_px);
    } else {
      std::snprintf(line, sizeof(line), "  %2zu  %-32s %6d  not used: %s\n", v, name.c_str(),
                    vr.points, vr.dropped_reason.c_str());
    }
    s << line;
  }
  std::snprintf(line, sizeof(line), "\n  Ceres: %d iterations, %.1f ms in all; ", iterations, solve_ms);
  s << line << termination << "\n";
  return s.str();
}

}  // namespace previz::calib
