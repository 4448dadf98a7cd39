// The rig bundle adjustment (multicam/detail/bundle.h). Lives at the folder root so the
// module's source glob picks it up; its header is internal (detail/).
#include <algorithm>
#include <cassert>
#include <cmath>
#include <map>
#include <memory>

#include <ceres/ceres.h>
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "calib/detail/projection.h"
#include "core/error.h"
#include "core/threads.h"
#include "core/lens_model.h"
#include "core/stats.h"
#include "multicam/detail/bundle.h"

namespace previz::multicam::detail {

namespace {

using calib::detail::kIntrinsicCount;
constexpr int kPoseSize = 7;  // Eigen quaternion (x y z w) + translation

// Poses are stored as (Eigen quaternion x y z w, translation) and perturbed on the left:
// R <- exp(d) R (a turn about the *world* axes for R_world_cam and R_world_board), t <- t + dt.
// The cost functions below return their Jacobians directly in that 6-dof tangent (in the first
// six of the seven ambient columns), so the manifold's Plus Jacobian is [I6; 0] — the usual
// trick of SLAM back ends (e.g. VINS-Mono's pose parameterization): exact, and it spares a
// 2x7 by 7x6 product per residual.
class PoseManifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return kPoseSize; }
  int TangentSize() const override { return 6; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    const Eigen::Map<const Eigen::Quaterniond> q(x);
    const Eigen::Map<const Eigen::Vector3d> w(delta);
    const double angle = w.norm();
    Eigen::Quaterniond dq = Eigen::Quaterniond::Identity();
    if (angle > 0) dq = Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle));
    Eigen::Map<Eigen::Quaterniond> q_out(x_plus_delta);
    q_out = (dq * q).normalized();
    for (int k = 0; k < 3; ++k) x_plus_delta[4 + k] = x[4 + k] + delta[3 + k];
    return true;
  }
  bool PlusJacobian(const double* x, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, kPoseSize, 6, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.topRows<6>().setIdentity();
    return true;
  }
  bool RightMultiplyByPlusJacobian(const double* x, const int num_rows, const double* ambient_matrix,
                                   double* tangent_matrix) const override {
    for (int r = 0; r < num_rows; ++r)
      for (int c = 0; c < 6; ++c) tangent_matrix[r * 6 + c] = ambient_matrix[r * kPoseSize + c];
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    const Eigen::Map<const Eigen::Quaterniond> qy(y), qx(x);
    const Eigen::AngleAxisd d(qy * qx.conjugate());
    Eigen::Map<Eigen::Vector3d> w_out(y_minus_x);
    w_out = d.axis() * d.angle();
    for (int k = 0; k < 3; ++k) y_minus_x[3 + k] = y[4 + k] - x[4 + k];
    return true;
  }
  bool MinusJacobian(const double* x, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 6, kPoseSize, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.leftCols<6>().setIdentity();
    return true;
  }
};

void poseToParams(const Pose& T, double* p) {
  const Eigen::Quaterniond q(T.linear());
  p[0] = q.x();
  p[1] = q.y();
  p[2] = q.z();
  p[3] = q.w();
  p[4] = T.translation().x();
  p[5] = T.translation().y();
  p[6] = T.translation().z();
}

Pose paramsToPose(const double* p) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::Quaterniond(p[3], p[0], p[1], p[2]).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(p[4], p[5], p[6]);
  return T;
}

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Observed minus predicted pixel of a board point, p_world = R_wb p_board + t_wb,
// p_cam = R_wc^T (p_world - C), projected with core/camera.h's model; and, when asked, its
// Jacobians (2 x 6, row-major, tangent of the pose as above) and w.r.t. the intrinsics (2 x 13,
// calib/detail/projection.h order). false when the point is behind the camera.
struct Linearized {
  Eigen::Vector2d r;
  Eigen::Matrix<double, 2, 6> J_cam, J_board;
  Eigen::Matrix<double, 2, kIntrinsicCount> J_intr;
};

bool rigResidual(const double* intr, LensModel model, const Eigen::Matrix3d& R_wc, const Eigen::Vector3d& C,
                 const Eigen::Matrix3d& R_wb, const Eigen::Vector3d& t_wb,
                 const Eigen::Vector3d& p_board, const Eigen::Vector2d& px, bool jacobians,
                 bool intr_jacobian, Linearized& out) {
  using namespace calib::detail;
  const Eigen::Vector3d rotated = R_wb * p_board;
  const Eigen::Vector3d rel = rotated + t_wb - C;
  const Eigen::Vector3d p = R_wc.transpose() * rel;
  if (!(p.z() > 1e-9)) return false;
  const double iz = 1.0 / p.z();
  const double x = p.x() * iz, y = p.y() * iz;
  // core/lens_model.h's lens and d(xd, yd) / d(x, y).
  const bool kb = model == LensModel::kKannalaBrandt;
  double xd, yd;
  Eigen::Matrix2d D;
  if (kb)
    lens::kannalaBrandtDistortWithJacobian(intr[kK1], intr[kK2], intr[kK3], intr[kK4], x, y, xd, yd, D(0, 0),
                                           D(0, 1), D(1, 1));
  else
    lens::brownDistortWithJacobian(intr[kK1], intr[kK2], intr[kP1], intr[kP2], intr[kK3], intr[kK4], intr[kK5],
                                   intr[kK6], x, y, xd, yd, D(0, 0), D(0, 1), D(1, 1));
  D(1, 0) = D(0, 1);
  const double fx = intr[kFx], fy = intr[kFy], s = intr[kSkew];
  out.r = px - Eigen::Vector2d(fx * xd + s * yd + intr[kCx], fy * yd + intr[kCy]);
  if (!jacobians) return true;
  Eigen::Matrix2d K;
  K << fx, s, 0, fy;
  Eigen::Matrix<double, 2, 3> P;
  P << iz, 0, -x * iz, 0, iz, -y * iz;
  // Residual = observed - predicted: the minus sign.
  const Eigen::Matrix<double, 2, 3> J_p = -K * D * P;      // d r / d p_cam
  const Eigen::Matrix<double, 2, 3> J_w = J_p * R_wc.transpose();  // d r / d p_world
  out.J_cam.leftCols<3>() = J_w * skew(rel);               // exp(-d) rel = rel + rel x d
  out.J_cam.rightCols<3>() = -J_w;
  out.J_board.leftCols<3>() = -J_w * skew(rotated);        // exp(d) v = v + d x v
  out.J_board.rightCols<3>() = J_w;
  if (!intr_jacobian) return true;
  out.J_intr.setZero();
  out.J_intr(0, kFx) = -xd;
  out.J_intr(0, kSkew) = -yd;
  out.J_intr(0, kCx) = -1.0;
  out.J_intr(1, kFy) = -yd;
  out.J_intr(1, kCy) = -1.0;
  if (kb) {
    // d(xd, yd) / d(k1 k2 k3 k4), then through K.
    Eigen::Matrix<double, 2, 4, Eigen::RowMajor> Dk;
    lens::kannalaBrandtCoefficientJacobian(x, y, Dk.data());
    const Eigen::Matrix<double, 2, 4> Jk = -K * Dk;
    out.J_intr.col(kK1) = Jk.col(0);
    out.J_intr.col(kK2) = Jk.col(1);
    out.J_intr.col(kK3) = Jk.col(2);
    out.J_intr.col(kK4) = Jk.col(3);
    return true;
  }
  // d(xd, yd) / d(k1 k2 p1 p2 k3 k4 k5 k6), then through K.
  Eigen::Matrix<double, 2, 8, Eigen::RowMajor> Dk;
  lens::brownCoefficientJacobian(intr[kK1], intr[kK2], intr[kK3], intr[kK4], intr[kK5], intr[kK6], x, y, Dk.data());
  const Eigen::Matrix<double, 2, 8> Jk = -K * Dk;
  out.J_intr.col(kK1) = Jk.col(0);
  out.J_intr.col(kK2) = Jk.col(1);
  out.J_intr.col(kP1) = Jk.col(2);
  out.J_intr.col(kP2) = Jk.col(3);
  out.J_intr.col(kK3) = Jk.col(4);
  out.J_intr.col(kK4) = Jk.col(5);
  out.J_intr.col(kK5) = Jk.col(6);
  out.J_intr.col(kK6) = Jk.col(7);
  return true;
}

Eigen::Matrix3d paramsRotation(const double* p) {
  return Eigen::Quaterniond(p[3], p[0], p[1], p[2]).toRotationMatrix();
}

void fillPoseJacobian(const Eigen::Matrix<double, 2, 6>& J, double* out) {
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 6; ++c) out[r * kPoseSize + c] = J(r, c);
    out[r * kPoseSize + 6] = 0.0;
  }
}

// Intrinsics held: baked in; parameter blocks (camera pose, board pose).
class FixedIntrinsicsCost final : public ceres::SizedCostFunction<2, kPoseSize, kPoseSize> {
 public:
  FixedIntrinsicsCost(const double* intr, LensModel model, const Eigen::Vector3d& p_board, const Eigen::Vector2d& px,
                      const double* weight)
      : model_(model), p_board_(p_board), px_(px), weight_(weight) {
    std::copy(intr, intr + kIntrinsicCount, intr_);
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* cam = parameters[0];
    const double* board = parameters[1];
    Linearized l;
    if (!rigResidual(intr_, model_, paramsRotation(cam), Eigen::Vector3d(cam[4], cam[5], cam[6]), paramsRotation(board),
                     Eigen::Vector3d(board[4], board[5], board[6]), p_board_, px_, jacobians != nullptr, false, l))
      return false;
    const double w = *weight_;
    residuals[0] = w * l.r.x();
    residuals[1] = w * l.r.y();
    if (jacobians) {
      if (jacobians[0]) fillPoseJacobian(w * l.J_cam, jacobians[0]);
      if (jacobians[1]) fillPoseJacobian(w * l.J_board, jacobians[1]);
    }
    return true;
  }

 private:
  double intr_[kIntrinsicCount];
  LensModel model_;
  Eigen::Vector3d p_board_;
  Eigen::Vector2d px_;
  const double* weight_;
};

// Intrinsics solved: parameter blocks (intrinsics, camera pose, board pose).
class FreeIntrinsicsCost final : public ceres::SizedCostFunction<2, kIntrinsicCount, kPoseSize, kPoseSize> {
 public:
  FreeIntrinsicsCost(LensModel model, const Eigen::Vector3d& p_board, const Eigen::Vector2d& px, const double* weight)
      : model_(model), p_board_(p_board), px_(px), weight_(weight) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* cam = parameters[1];
    const double* board = parameters[2];
    Linearized l;
    const bool want = jacobians != nullptr;
    if (!rigResidual(parameters[0], model_, paramsRotation(cam), Eigen::Vector3d(cam[4], cam[5], cam[6]),
                     paramsRotation(board), Eigen::Vector3d(board[4], board[5], board[6]), p_board_, px_, want,
                     want && jacobians[0] != nullptr, l))
      return false;
    const double w = *weight_;
    residuals[0] = w * l.r.x();
    residuals[1] = w * l.r.y();
    if (want) {
      if (jacobians[0]) {
        Eigen::Map<Eigen::Matrix<double, 2, kIntrinsicCount, Eigen::RowMajor>> J(jacobians[0]);
        J = w * l.J_intr;
      }
      if (jacobians[1]) fillPoseJacobian(w * l.J_cam, jacobians[1]);
      if (jacobians[2]) fillPoseJacobian(w * l.J_board, jacobians[2]);
    }
    return true;
  }

 private:
  LensModel model_;
  Eigen::Vector3d p_board_;
  Eigen::Vector2d px_;
  const double* weight_;
};

// A held camera whose centre is the rig's scale times its own (BundleProblem::rig_scale):
// parameter blocks (board pose, rig scale). d r / d scale = (d r / d C) C0.
class ScaledHeldCameraCost final : public ceres::SizedCostFunction<2, kPoseSize, 1> {
 public:
  ScaledHeldCameraCost(const double* intr, LensModel model, const Pose& T_world_cam, const Eigen::Vector3d& p_board,
                       const Eigen::Vector2d& px, const double* weight)
      : model_(model), R_wc_(T_world_cam.linear()), C_(T_world_cam.translation()), p_board_(p_board), px_(px), weight_(weight) {
    std::copy(intr, intr + kIntrinsicCount, intr_);
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* board = parameters[0];
    const double scale = parameters[1][0];
    Linearized l;
    if (!rigResidual(intr_, model_, R_wc_, scale * C_, paramsRotation(board), Eigen::Vector3d(board[4], board[5], board[6]),
                     p_board_, px_, jacobians != nullptr, false, l))
      return false;
    const double w = *weight_;
    residuals[0] = w * l.r.x();
    residuals[1] = w * l.r.y();
    if (jacobians) {
      if (jacobians[0]) fillPoseJacobian(w * l.J_board, jacobians[0]);
      if (jacobians[1]) {
        const Eigen::Vector2d J_scale = w * l.J_cam.rightCols<3>() * C_;
        jacobians[1][0] = J_scale.x();
        jacobians[1][1] = J_scale.y();
      }
    }
    return true;
  }

 private:
  double intr_[kIntrinsicCount];
  LensModel model_;
  Eigen::Matrix3d R_wc_;
  Eigen::Vector3d C_, p_board_;
  Eigen::Vector2d px_;
  const double* weight_;
};

// The rig's scale enters the solve (free, or held at a value other than 1): every camera held.
bool scaledRig(const BundleProblem& p) { return p.rig_scale_free || p.rig_scale != 1.0; }

// Parameter storage of one solve.
struct Params {
  std::vector<std::array<double, kPoseSize>> cams, boards;
  std::vector<std::array<double, kIntrinsicCount>> intr;
  std::vector<LensModel> models;
  double scale = 1.0;

  explicit Params(const BundleProblem& p) : cams(p.cameras.size()), boards(p.boards.size()),
                                            intr(p.cameras.size()), scale(p.rig_scale) {
    for (size_t i = 0; i < p.cameras.size(); ++i) {
      poseToParams(p.cameras[i].T_world_cam, cams[i].data());
      calib::detail::cameraToVector(p.cameras[i].camera, intr[i].data());
      models.push_back(p.cameras[i].camera.dist.model);
    }
    for (size_t j = 0; j < p.boards.size(); ++j) poseToParams(p.boards[j].T_world_board, boards[j].data());
  }
  void writeBack(BundleProblem& p) const {
    for (size_t i = 0; i < p.cameras.size(); ++i) {
      p.cameras[i].T_world_cam = paramsToPose(cams[i].data());
      if (!p.cameras[i].free_intrinsics.empty()) calib::detail::vectorToCamera(intr[i].data(), p.cameras[i].camera.dist.model, p.cameras[i].camera);
    }
    for (size_t j = 0; j < p.boards.size(); ++j) p.boards[j].T_world_board = paramsToPose(boards[j].data());
    p.rig_scale = scale;
  }
  // Residual (huge when the point is behind the camera) and whether it is in front.
  Eigen::Vector2d residual(const BundlePoint& pt, bool* in_front = nullptr) const {
    const double* cam = cams[pt.camera].data();
    const double* board = boards[pt.board].data();
    Linearized l;
    const bool ok = rigResidual(intr[pt.camera].data(), models[pt.camera], paramsRotation(cam),
                                scale * Eigen::Vector3d(cam[4], cam[5], cam[6]), paramsRotation(board),
                                Eigen::Vector3d(board[4], board[5], board[6]), pt.p_board, pt.px, false, false, l);
    if (in_front) *in_front = ok;
    return ok && l.r.allFinite() ? l.r : Eigen::Vector2d(1e9, 1e9);
  }
  bool inFront(const BundlePoint& pt) const {
    bool ok = false;
    residual(pt, &ok);
    return ok;
  }
};

bool validIndex(const BundleProblem& p, const BundlePoint& pt) {
  return pt.camera >= 0 && pt.camera < static_cast<int>(p.cameras.size()) && pt.board >= 0 &&
         pt.board < static_cast<int>(p.boards.size());
}

bool hasFreeParameter(const BundleProblem& p, const BundlePoint& pt) {
  const BundleCamera& c = p.cameras[pt.camera];
  return !c.pose_fixed || !c.free_intrinsics.empty() || !p.boards[pt.board].fixed || p.rig_scale_free;
}

// Drops (camera, board) views left with fewer than min_points active points: a board pose on a
// handful of surviving points is a lever for whatever outliers remain among them.
int dropThinViews(BundleProblem& p, int min_points) {
  std::map<std::pair<int, int>, int> count;
  for (const BundlePoint& pt : p.points)
    if (pt.active) ++count[{pt.camera, pt.board}];
  int dropped = 0;
  for (BundlePoint& pt : p.points) {
    if (pt.active && count[{pt.camera, pt.board}] < min_points) {
      pt.active = false;
      ++dropped;
    }
  }
  return dropped;
}

// Noise groups: per camera, its static-scene points and its other points. Sets every point's
// weight to sigma(all) / sigma(group), sigmas robust (median |r| / 1.1774) over the active
// points; a group under 30 points keeps weight 1. Returns true when a weight moved by more than
// 10 % (the solve is worth repeating; the median of a few hundred residuals is itself ~7 % noisy).
bool updateWeights(BundleProblem& p, const std::vector<double>& norms) {
  constexpr int kMinGroupPoints = 30;
  std::map<std::pair<int, bool>, std::vector<double>> groups;
  std::vector<double> all;
  for (size_t k = 0; k < p.points.size(); ++k) {
    const BundlePoint& pt = p.points[k];
    if (!pt.active) continue;
    groups[{pt.camera, p.boards[pt.board].static_scene >= 0}].push_back(norms[k]);
    all.push_back(norms[k]);
  }
  const double sigma_all = median(all) / 1.1774;
  if (!(sigma_all > 0)) return false;
  std::map<std::pair<int, bool>, double> weight;
  for (auto& [key, v] : groups) {
    const double sigma = median(v) / 1.1774;
    weight[key] = static_cast<int>(v.size()) >= kMinGroupPoints && sigma > 0
                      ? std::clamp(sigma_all / sigma, 0.1, 10.0)
                      : 1.0;
  }
  bool moved = false;
  for (BundlePoint& pt : p.points) {
    const auto it = weight.find({pt.camera, p.boards[pt.board].static_scene >= 0});
    const double w = it == weight.end() ? 1.0 : it->second;
    moved = moved || std::abs(w / pt.weight - 1.0) > 0.10;
    pt.weight = w;
  }
  return moved;
}

}  // namespace

std::vector<int> defaultFreeIntrinsics(LensModel model) {
  using namespace calib::detail;
  if (model == LensModel::kKannalaBrandt) return {kFx, kFy, kCx, kCy, kK1, kK2};
  return {kFx, kFy, kCx, kCy, kK1, kK2, kP1, kP2};
}

Eigen::Vector2d bundleResidual(const BundleProblem& problem, const BundlePoint& point) {
  double intr[kIntrinsicCount];
  calib::detail::cameraToVector(problem.cameras[point.camera].camera, intr);
  const Pose& T_wc = problem.cameras[point.camera].T_world_cam;
  const Pose& T_wb = problem.boards[point.board].T_world_board;
  Linearized l;
  const bool ok = rigResidual(intr, problem.cameras[point.camera].camera.dist.model, T_wc.linear(), problem.rig_scale * T_wc.translation(), T_wb.linear(),
                              T_wb.translation(), point.p_board, point.px, false, false, l);
  return ok && l.r.allFinite() ? l.r : Eigen::Vector2d(1e9, 1e9);
}

BundleStats solveBundle(BundleProblem& problem, const BundleOptions& options) {
  BundleStats stats;
  Params params(problem);
  for (BundlePoint& pt : problem.points) {
    if (!pt.active) continue;
    if (!validIndex(problem, pt) || !params.inFront(pt)) {
      pt.active = false;
      ++stats.rejected;
    }
  }
  stats.rejected += dropThinViews(problem, options.min_points);

  ceres::Problem::Options problem_options;
  problem_options.enable_fast_removal = true;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem ceres_problem(problem_options);
  ceres::HuberLoss loss(options.huber_px);
  PoseManifold pose_manifold;
  std::vector<std::unique_ptr<ceres::Manifold>> intrinsic_manifolds;

  const bool scaled = scaledRig(problem);
  assert(!scaled || std::all_of(problem.cameras.begin(), problem.cameras.end(), [](const BundleCamera& c) {
           return c.pose_fixed && c.free_intrinsics.empty();
         }));
  std::vector<ceres::ResidualBlockId> blocks(problem.points.size(), nullptr);
  std::vector<bool> cam_used(problem.cameras.size(), false), board_used(problem.boards.size(), false);
  for (size_t k = 0; k < problem.points.size(); ++k) {
    const BundlePoint& pt = problem.points[k];
    if (!pt.active || !hasFreeParameter(problem, pt)) continue;
    double* cam = params.cams[pt.camera].data();
    double* board = params.boards[pt.board].data();
    if (scaled) {
      blocks[k] = ceres_problem.AddResidualBlock(
          new ScaledHeldCameraCost(params.intr[pt.camera].data(), params.models[pt.camera],
                                   problem.cameras[pt.camera].T_world_cam, pt.p_board,
                                   pt.px, &problem.points[k].weight),
          &loss, board, &params.scale);
    } else if (problem.cameras[pt.camera].free_intrinsics.empty()) {
      blocks[k] = ceres_problem.AddResidualBlock(
          new FixedIntrinsicsCost(params.intr[pt.camera].data(), params.models[pt.camera], pt.p_board, pt.px, &problem.points[k].weight), &loss,
          cam, board);
    } else {
      blocks[k] = ceres_problem.AddResidualBlock(new FreeIntrinsicsCost(params.models[pt.camera], pt.p_board, pt.px, &problem.points[k].weight), &loss,
                                                 params.intr[pt.camera].data(), cam, board);
    }
    cam_used[pt.camera] = true;
    board_used[pt.board] = true;
  }
  bool any_free_board = false, any_free_camera = problem.rig_scale_free;
  ceres::ParameterBlockOrdering* ordering = new ceres::ParameterBlockOrdering;
  if (scaled && ceres_problem.HasParameterBlock(&params.scale)) {
    if (!problem.rig_scale_free) ceres_problem.SetParameterBlockConstant(&params.scale);
    ordering->AddElementToGroup(&params.scale, 1);
  }
  for (size_t i = 0; i < problem.cameras.size(); ++i) {
    if (!cam_used[i] || scaled) continue;  // a scaled rig's cameras are baked into their costs
    const BundleCamera& c = problem.cameras[i];
    any_free_camera = any_free_camera || !c.pose_fixed || !c.free_intrinsics.empty();
    ceres_problem.SetManifold(params.cams[i].data(), &pose_manifold);
    if (c.pose_fixed) ceres_problem.SetParameterBlockConstant(params.cams[i].data());
    ordering->AddElementToGroup(params.cams[i].data(), 1);
    if (!c.free_intrinsics.empty()) {
      // Held: what is not free, and the terms the camera's lens model does not have (Brown's k4 k5
      // k6 are its rational terms: held unless listed free).
      const bool kb = c.camera.dist.model == LensModel::kKannalaBrandt;
      std::vector<int> held;
      for (int k = 0; k < kIntrinsicCount; ++k)
        if (std::find(c.free_intrinsics.begin(), c.free_intrinsics.end(), k) == c.free_intrinsics.end() ||
            (kb && (k == calib::detail::kP1 || k == calib::detail::kP2 || k == calib::detail::kK5 ||
                    k == calib::detail::kK6)))
          held.push_back(k);
      if (!held.empty()) {
        intrinsic_manifolds.push_back(std::make_unique<ceres::SubsetManifold>(kIntrinsicCount, held));
        ceres_problem.SetManifold(params.intr[i].data(), intrinsic_manifolds.back().get());
      }
      ordering->AddElementToGroup(params.intr[i].data(), 1);
    }
  }
  for (size_t j = 0; j < problem.boards.size(); ++j) {
    if (!board_used[j]) continue;
    ceres_problem.SetManifold(params.boards[j].data(), &pose_manifold);
    if (problem.boards[j].fixed) {
      ceres_problem.SetParameterBlockConstant(params.boards[j].data());
      ordering->AddElementToGroup(params.boards[j].data(), 1);
    } else {
      any_free_board = true;
      ordering->AddElementToGroup(params.boards[j].data(), 0);
    }
  }

  ceres::Solver::Options solver_options;
  // Boards first (a 6-dof block each, independent given the cameras), then a small dense
  // camera system: the rig's Schur complement has at most a few hundred unknowns.
  // Only boards free (cameras held): independent 6x6 blocks, a sparse Cholesky takes them.
  // Only cameras free: a small dense system.
  const bool schur = any_free_board && any_free_camera;
  if (schur) {
    solver_options.linear_solver_type = ceres::DENSE_SCHUR;
    solver_options.linear_solver_ordering.reset(ordering);
  } else {
    delete ordering;
    solver_options.linear_solver_type = any_free_board ? ceres::SPARSE_NORMAL_CHOLESKY : ceres::DENSE_NORMAL_CHOLESKY;
  }
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = 1e-10;
  solver_options.gradient_tolerance = 1e-12;
  solver_options.parameter_tolerance = 1e-10;
  solver_options.num_threads = resolveThreads(options.threads);

  if (ceres_problem.NumResidualBlocks() == 0) {
    params.writeBack(problem);
    stats.message = "nothing to solve";
    return stats;
  }
  for (int round = 0;; ++round) {
    ceres::Solver::Summary summary;
    ceres::Solve(solver_options, &ceres_problem, &summary);
    stats.iterations += static_cast<int>(summary.iterations.size());
    stats.message = summary.message;
    if (!summary.IsSolutionUsable()) throw Error("rig bundle adjustment failed: " + summary.message);
    if (round >= options.outlier_rounds) break;

    std::vector<double> norms(problem.points.size(), 0.0);
    for (size_t k = 0; k < problem.points.size(); ++k)
      if (problem.points[k].active) norms[k] = params.residual(problem.points[k]).norm();
    const bool reweighted = options.noise_groups && updateWeights(problem, norms);
    std::vector<double> weighted;
    for (size_t k = 0; k < problem.points.size(); ++k)
      if (problem.points[k].active) weighted.push_back(problem.points[k].weight * norms[k]);
    // 2-D Gaussian residuals: median |r| = 1.1774 sigma.
    const double threshold =
        options.outlier_px > 0 ? options.outlier_px : std::max(1.0, 5.0 * median(weighted) / 1.1774);
    int rejected = 0;
    for (size_t k = 0; k < problem.points.size(); ++k) {
      BundlePoint& pt = problem.points[k];
      if (pt.active && pt.weight * norms[k] > threshold) {
        pt.active = false;
        ++rejected;
      }
    }
    if (rejected == 0 && !reweighted) break;
    rejected += dropThinViews(problem, options.min_points);
    stats.rejected += rejected;
    ++stats.rejection_rounds;
    for (size_t k = 0; k < problem.points.size(); ++k) {
      if (!problem.points[k].active && blocks[k] != nullptr) {
        ceres_problem.RemoveResidualBlock(blocks[k]);
        blocks[k] = nullptr;
      }
    }
    // A board left without residuals leaves the problem (Ceres wants no orphan blocks in the
    // Schur ordering).
    std::vector<bool> still_used(problem.boards.size(), false);
    for (size_t k = 0; k < problem.points.size(); ++k)
      if (blocks[k] != nullptr) still_used[problem.points[k].board] = true;
    for (size_t j = 0; j < problem.boards.size(); ++j) {
      if (board_used[j] && !still_used[j]) {
        ceres_problem.RemoveParameterBlock(params.boards[j].data());
        if (schur) solver_options.linear_solver_ordering->Remove(params.boards[j].data());
        board_used[j] = false;
      }
    }
    if (ceres_problem.NumResidualBlocks() == 0) break;
  }
  params.writeBack(problem);
  return stats;
}

double bundleSigmaPx(const BundleProblem& problem) {
  double ssr = 0;
  int n = 0;
  std::vector<bool> cam_seen(problem.cameras.size(), false), board_seen(problem.boards.size(), false);
  for (const BundlePoint& pt : problem.points) {
    if (!pt.active) continue;
    ssr += pt.weight * pt.weight * bundleResidual(problem, pt).squaredNorm();
    ++n;
    cam_seen[pt.camera] = true;
    board_seen[pt.board] = true;
  }
  int free = 0;
  for (size_t i = 0; i < problem.cameras.size(); ++i) {
    if (!cam_seen[i]) continue;
    if (!problem.cameras[i].pose_fixed) free += 6;
    free += static_cast<int>(problem.cameras[i].free_intrinsics.size());
  }
  for (size_t j = 0; j < problem.boards.size(); ++j)
    if (board_seen[j] && !problem.boards[j].fixed) free += 6;
  if (problem.rig_scale_free) free += 1;
  const int dof = 2 * n - free;
  return dof > 0 ? std::sqrt(ssr / dof) : 0.0;
}

std::vector<Eigen::Matrix<double, 6, 6>> bundleCameraCovariances(const BundleProblem& problem,
                                                                 double sigma_px, bool* ok,
                                                                 double* rig_scale_sigma) {
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  const int n_cams = static_cast<int>(problem.cameras.size());
  std::vector<Mat6> out(n_cams, Mat6::Zero());
  if (ok) *ok = false;
  if (rig_scale_sigma) *rig_scale_sigma = 0;

  // Camera-side unknowns: 6 per free pose, then the free intrinsics.
  std::vector<int> pose_offset(n_cams, -1), intr_offset(n_cams, -1);
  int n_c = 0;
  for (int i = 0; i < n_cams; ++i) {
    if (!problem.cameras[i].pose_fixed) {
      pose_offset[i] = n_c;
      n_c += 6;
    }
    if (!problem.cameras[i].free_intrinsics.empty()) {
      intr_offset[i] = n_c;
      n_c += static_cast<int>(problem.cameras[i].free_intrinsics.size());
    }
  }
  const int scale_offset = problem.rig_scale_free ? n_c++ : -1;
  if (n_c == 0) {
    if (ok) *ok = true;
    return out;
  }
  // One point's residual and Jacobian: camera-side columns as (unknown index, column).
  std::vector<std::pair<int, Eigen::Vector2d>> cols;
  auto linearize = [&](const BundlePoint& pt, Linearized& l) {
    const BundleCamera& cam = problem.cameras[pt.camera];
    const BundleBoard& board = problem.boards[pt.board];
    double intr[kIntrinsicCount];
    calib::detail::cameraToVector(cam.camera, intr);
    if (!rigResidual(intr, cam.camera.dist.model, cam.T_world_cam.linear(), problem.rig_scale * cam.T_world_cam.translation(),
                     board.T_world_board.linear(), board.T_world_board.translation(), pt.p_board, pt.px, true, true,
                     l))
      return false;
    l.r *= pt.weight;
    l.J_cam *= pt.weight;
    l.J_board *= pt.weight;
    l.J_intr *= pt.weight;
    cols.clear();
    if (pose_offset[pt.camera] >= 0)
      for (int k = 0; k < 6; ++k) cols.push_back({pose_offset[pt.camera] + k, l.J_cam.col(k)});
    if (intr_offset[pt.camera] >= 0) {
      const std::vector<int>& free = cam.free_intrinsics;
      for (size_t k = 0; k < free.size(); ++k)
        cols.push_back({intr_offset[pt.camera] + static_cast<int>(k), l.J_intr.col(free[k])});
    }
    if (scale_offset >= 0) cols.push_back({scale_offset, l.J_cam.rightCols<3>() * cam.T_world_cam.translation()});
    return true;
  };

  Eigen::MatrixXd H_cc = Eigen::MatrixXd::Zero(n_c, n_c);
  std::vector<Mat6> H_bb(problem.boards.size(), Mat6::Zero());
  std::vector<Eigen::MatrixXd> H_bc(problem.boards.size());
  for (const BundlePoint& pt : problem.points) {
    Linearized l;
    if (!pt.active || !linearize(pt, l)) continue;
    for (const auto& a : cols)
      for (const auto& b : cols) H_cc(a.first, b.first) += a.second.dot(b.second);
    if (problem.boards[pt.board].fixed) continue;
    const Eigen::Matrix<double, 2, 6>& Jb = l.J_board;
    H_bb[pt.board] += Jb.transpose() * Jb;
    Eigen::MatrixXd& Hbc = H_bc[pt.board];
    if (Hbc.size() == 0) Hbc = Eigen::MatrixXd::Zero(6, n_c);
    for (const auto& a : cols) Hbc.col(a.first) += Jb.transpose() * a.second;
  }
  // Schur complement: the boards marginalised out.
  for (size_t j = 0; j < problem.boards.size(); ++j) {
    if (H_bc[j].size() == 0) continue;
    const Eigen::LDLT<Mat6> H_bb_inv(H_bb[j]);
    if (H_bb_inv.info() != Eigen::Success) continue;
    H_cc -= H_bc[j].transpose() * H_bb_inv.solve(H_bc[j]);
  }
  H_cc = 0.5 * (H_cc + H_cc.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(H_cc);
  if (eig.info() != Eigen::Success) return out;
  const double max_ev = eig.eigenvalues().maxCoeff();
  if (!(eig.eigenvalues().minCoeff() > 1e-12 * max_ev)) return out;
  const Eigen::MatrixXd S_inv =
      eig.eigenvectors() * eig.eigenvalues().cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();

  const Eigen::MatrixXd cov = S_inv * (sigma_px * sigma_px);
  for (int i = 0; i < n_cams; ++i)
    if (pose_offset[i] >= 0) out[i] = cov.block<6, 6>(pose_offset[i], pose_offset[i]);
  if (rig_scale_sigma && scale_offset >= 0) *rig_scale_sigma = std::sqrt(cov(scale_offset, scale_offset));
  if (ok) *ok = true;
  return out;
}

}  // namespace previz::multicam::detail
