#include "calib/validation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <limits>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <ceres/jet.h>
#include <ceres/rotation.h>

#include "calib/detail/projection.h"
#include "core/error.h"

namespace previz::calib {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

[[noreturn]] void failField(const char* who, const std::string& field, const std::string& what) {
  ErrorContext context;
  context.field = field;
  throw Error(std::string(who) + ": " + field + " " + what, context);
}

ImageGrid makeGrid(cv::Size size, int cols) {
  ImageGrid g;
  g.image_size = size;
  g.cols = cols;
  g.rows = std::max(2, static_cast<int>(std::lround(static_cast<double>(cols) * size.height / size.width)));
  return g;
}

// The furthest used point from the camera's principal point over the results' residuals, for a
// lens that is not Brown–Conrady (ImageGrid::data_radius_px); 0 (the whole image) otherwise.
void limitToData(ImageGrid& g, const Camera& camera, std::initializer_list<const IntrinsicsResult*> results) {
  if (camera.dist.isBrown()) return;
  g.principal_point = Eigen::Vector2d(camera.cx, camera.cy);
  for (const IntrinsicsResult* r : results)
    for (const PointResidual& p : r->residuals)
      if (!p.rejected) g.data_radius_px = std::max(g.data_radius_px, (p.px - g.principal_point).norm());
}

double worstSigma(const Eigen::Matrix2d& C) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 * (C + C.transpose()));
  return std::sqrt(std::max(0.0, eig.eigenvalues()(1)));
}

// Pixel of a camera-frame point with its Jacobians wrt intrinsics (2 x kIntrinsicCount) and the point (2 x 3).
void projectWithJacobians(const double* intr, LensModel model, const Eigen::Vector3d& p,
                          Eigen::Matrix<double, 2, kIntrinsicCount>& J_intr,
                          Eigen::Matrix<double, 2, 3>& J_point) {
  using Jet = ceres::Jet<double, kIntrinsicCount + 3>;
  Jet ji[kIntrinsicCount], jp[3];
  for (int i = 0; i < kIntrinsicCount; ++i) ji[i] = Jet(intr[i], i);
  for (int i = 0; i < 3; ++i) jp[i] = Jet(p(i), kIntrinsicCount + i);
  Jet uv[2];
  detail::projectCameraPoint(ji, jp, 0.0, model, uv);
  for (int r = 0; r < 2; ++r) {
    J_intr.row(r) = uv[r].v.head<kIntrinsicCount>().transpose();
    J_point.row(r) = uv[r].v.tail<3>().transpose();
  }
}

// Projection difference of camera b against camera a over grid pixels: project_b(R ray_a(q)) - q,
// with R the best-fit rotation when fit_rotation (over the pixels inside). Entries of `valid`
// false where a has no ray or the pixel is not inside.
struct DiffField {
  std::vector<Eigen::Vector2d> d;
  std::vector<bool> valid;
};

DiffField projectionDiff(const double* intr_a, const double* intr_b, const Camera& size_ref,
                         const std::vector<Eigen::Vector2d>& pixels, const std::vector<bool>& inside,
                         bool fit_rotation) {
  Camera a = size_ref, b = size_ref;
  detail::vectorToCamera(intr_a, size_ref.dist.model, a);
  detail::vectorToCamera(intr_b, size_ref.dist.model, b);
  DiffField out;
  out.d.assign(pixels.size(), Eigen::Vector2d::Zero());
  out.valid.assign(pixels.size(), false);
  std::vector<Eigen::Vector3d> rays(pixels.size());
  for (size_t k = 0; k < pixels.size(); ++k) {
    if (!inside[k]) continue;
    const auto ray = a.unproject(pixels[k]);
    if (!ray) continue;
    rays[k] = *ray;
    out.valid[k] = true;
  }
  double omega[3] = {0, 0, 0};
  auto evaluate = [&](const double* w, std::vector<Eigen::Vector2d>& d,
                      Eigen::Matrix<double, 3, 3>* JtJ, Eigen::Vector3d* Jtr) {
    using Jet = ceres::Jet<double, 3>;
    const Jet jw[3] = {Jet(w[0], 0), Jet(w[1], 1), Jet(w[2], 2)};
    Jet ji[kIntrinsicCount];
    for (int i = 0; i < kIntrinsicCount; ++i) ji[i] = Jet(intr_b[i]);
    if (JtJ) JtJ->setZero();
    if (Jtr) Jtr->setZero();
    for (size_t k = 0; k < pixels.size(); ++k) {
      if (!out.valid[k]) continue;
      const Jet r[3] = {Jet(rays[k].x()), Jet(rays[k].y()), Jet(rays[k].z())};
      Jet p[3], uv[2];
      ceres::AngleAxisRotatePoint(jw, r, p);
      detail::projectCameraPoint(ji, p, 0.0, b.dist.model, uv);
      d[k] = Eigen::Vector2d(uv[0].a - pixels[k].x(), uv[1].a - pixels[k].y());
      if (JtJ) {
        Eigen::Matrix<double, 2, 3> J;
        J.row(0) = uv[0].v.transpose();
        J.row(1) = uv[1].v.transpose();
        *JtJ += J.transpose() * J;
        *Jtr += J.transpose() * d[k];
      }
    }
  };
  if (fit_rotation) {
    // Gauss–Newton on the 3 rotation parameters, run to convergence so that numerical
    // derivatives of the whole difference (rotation fit included) are clean.
    std::vector<Eigen::Vector2d> d(pixels.size());
    for (int it = 0; it < 30; ++it) {
      Eigen::Matrix3d JtJ;
      Eigen::Vector3d Jtr;
      evaluate(omega, d, &JtJ, &Jtr);
      const Eigen::Vector3d step = -JtJ.ldlt().solve(Jtr);
      for (int i = 0; i < 3; ++i) omega[i] += step(i);
      if (step.norm() < 1e-15) break;
    }
  }
  evaluate(omega, out.d, nullptr, nullptr);
  return out;
}

}  // namespace

const char* toString(CrossValidationSplit split) {
  return split == CrossValidationSplit::kAlternate ? "alternate" : "centre-edge";
}

const char* toString(UncertaintyMode mode) {
  return mode == UncertaintyMode::kIntrinsicsOnly ? "intrinsics-only" : "mean-frames";
}

void UncertaintyOptions::validate() const {
  if (grid_cols < 2) failField("uncertainty", "grid_cols", "must be >= 2 (got " + std::to_string(grid_cols) + ")");
  if (!(distance_m > 0) || !std::isfinite(distance_m))
    failField("uncertainty", "distance_m", "must be > 0 (got " + std::to_string(distance_m) + ")");
}

void CrossValidationOptions::validate() const {
  if (grid_cols < 2) failField("cross-validate", "grid_cols", "must be >= 2 (got " + std::to_string(grid_cols) + ")");
  if (!(max_normalised_rms > 0))
    failField("cross-validate", "max_normalised_rms", "must be > 0");
  solve.validate();
}

UncertaintyMap projectionUncertainty(const IntrinsicsResult& result,
                                     const UncertaintyOptions& options) {
  options.validate();
  if (!result.covariance_ok) {
    throw Error("uncertainty: the calibration has no covariance (" + result.covariance_message + ")");
  }
  const bool mean_frames = options.mode == UncertaintyMode::kMeanFrames;
  const int n_views = static_cast<int>(result.joint_views.size());
  if (mean_frames && (n_views == 0 || result.joint_covariance.rows() != kIntrinsicCount + 6 * n_views)) {
    throw Error("uncertainty: mean-frames needs the joint covariance (IntrinsicsOptions::joint_covariance)");
  }
  UncertaintyMap map;
  map.mode = options.mode;
  map.grid = makeGrid(result.image_size, options.grid_cols);
  limitToData(map.grid, result.camera, {&result});
  map.sigma_px = cv::Mat(map.grid.rows, map.grid.cols, CV_64F, cv::Scalar(kNaN));
  const Camera& camera = result.camera;
  double intr[kIntrinsicCount];
  detail::cameraToVector(camera, intr);

  // Each view's pose and the derivative of its mapped point wrt that pose (mean-frames).
  std::vector<std::array<double, 6>> poses;
  for (int view : result.joint_views) {
    Eigen::Vector3d r, t;
    poseToRvecTvec(result.views[view].T_cam_board, r, t);
    poses.push_back({r.x(), r.y(), r.z(), t.x(), t.y(), t.z()});
  }
  const Eigen::MatrixXd& cov = mean_frames ? result.joint_covariance : result.covariance;

#pragma omp parallel for schedule(static)
  for (int r = 0; r < map.grid.rows; ++r) {
    for (int c = 0; c < map.grid.cols; ++c) {
      if (!map.grid.inside(r, c)) continue;
      const auto ray = camera.unproject(map.grid.pixel(r, c));
      if (!ray) continue;
      Eigen::Matrix<double, 2, kIntrinsicCount> J_intr;
      Eigen::Matrix<double, 2, 3> J_point;
      const Eigen::Vector3d p_cam = mean_frames ? Eigen::Vector3d(*ray / ray->z() * options.distance_m)
                                                : Eigen::Vector3d(*ray);
      projectWithJacobians(intr, camera.dist.model, p_cam, J_intr, J_point);
      Eigen::MatrixXd J = Eigen::MatrixXd::Zero(2, cov.rows());
      J.leftCols<kIntrinsicCount>() = J_intr;
      if (mean_frames) {
        for (int i = 0; i < n_views; ++i) {
          // p_cam = mean_i T_i(theta_i) (T_i^-1 p_cam): derivative of T_i p_b wrt (aa_i, t_i).
          const Pose& T = result.views[result.joint_views[i]].T_cam_board;
          const Eigen::Vector3d p_b = T.inverse() * p_cam;
          using Jet = ceres::Jet<double, 3>;
          const Jet aa[3] = {Jet(poses[i][0], 0), Jet(poses[i][1], 1), Jet(poses[i][2], 2)};
          const Jet pb[3] = {Jet(p_b.x()), Jet(p_b.y()), Jet(p_b.z())};
          Jet rotated[3];
          ceres::AngleAxisRotatePoint(aa, pb, rotated);
          Eigen::Matrix<double, 3, 6> dp;
          for (int k = 0; k < 3; ++k) dp.block<1, 3>(k, 0) = rotated[k].v.transpose();
          dp.rightCols<3>() = Eigen::Matrix3d::Identity();
          J.block(0, kIntrinsicCount + 6 * i, 2, 6) = J_point * dp / n_views;
        }
      }
      const Eigen::Matrix2d C = J * cov * J.transpose();
      map.sigma_px.at<double>(r, c) = worstSigma(C);
    }
  }
  double sum = 0;
  int count = 0;
  for (int r = 0; r < map.grid.rows; ++r) {
    for (int c = 0; c < map.grid.cols; ++c) {
      const double s = map.sigma_px.at<double>(r, c);
      if (!std::isfinite(s)) continue;
      sum += s;
      ++count;
      map.max_px = std::max(map.max_px, s);
    }
  }
  map.mean_px = count > 0 ? sum / count : kNaN;
  map.centre_px = map.sigma_px.at<double>(map.grid.rows / 2, map.grid.cols / 2);
  const int R = map.grid.rows - 1, C = map.grid.cols - 1;
  map.corners_px = 0.25 * (map.sigma_px.at<double>(0, 0) + map.sigma_px.at<double>(0, C) +
                           map.sigma_px.at<double>(R, 0) + map.sigma_px.at<double>(R, C));
  return map;
}

CrossValidationResult crossValidate(const std::vector<ViewObservations>& views,
                                    const BoardSpec& board, const CrossValidationOptions& options) {
  options.validate();
  std::vector<const ViewObservations*> usable_views;
  for (const ViewObservations& v : views) {
    if (!v.found() || v.rejected ||
        static_cast<int>(v.points.size()) < options.solve.min_points_per_view) {
      continue;
    }
    usable_views.push_back(&v);
  }
  const int usable = static_cast<int>(usable_views.size());
  std::vector<ViewObservations> half[2];
  if (options.split == CrossValidationSplit::kAlternate) {
    for (int i = 0; i < usable; ++i) half[i % 2].push_back(*usable_views[i]);
  } else {
    std::vector<std::pair<double, int>> radius;
    for (int i = 0; i < usable; ++i) {
      const ViewObservations& v = *usable_views[i];
      Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
      for (const Observation& o : v.points) centroid += o.px;
      centroid /= static_cast<double>(v.points.size());
      const Eigen::Vector2d centre(0.5 * (v.image_size.width - 1), 0.5 * (v.image_size.height - 1));
      radius.push_back({(centroid - centre).norm(), i});
    }
    std::stable_sort(radius.begin(), radius.end());
    for (int k = 0; k < usable; ++k) half[k < usable / 2 ? 0 : 1].push_back(*usable_views[radius[k].second]);
  }
  CrossValidationResult out;
  IntrinsicsOptions solve = options.solve;
  solve.compute_covariance = true;
  solve.joint_covariance = false;
  for (int h = 0; h < 2; ++h) {
    if (static_cast<int>(half[h].size()) < solve.min_views) {
      throw Error("cross-validate: " + std::to_string(usable) + " usable views make halves of " +
                  std::to_string(half[0].size()) + " and " + std::to_string(half[1].size()) +
                  " (need " + std::to_string(solve.min_views) + " each)");
    }
  }
  out.a = calibrateIntrinsics(half[0], board, solve);
  out.b = calibrateIntrinsics(half[1], board, solve);
  if (!out.a.covariance_ok || !out.b.covariance_ok) {
    throw Error("cross-validate: a half has no covariance (" + out.a.covariance_message +
                out.b.covariance_message + ")");
  }
  out.grid = makeGrid(out.a.image_size, options.grid_cols);
  limitToData(out.grid, out.a.camera, {&out.a, &out.b});
  std::vector<Eigen::Vector2d> pixels;
  std::vector<bool> inside;
  for (int r = 0; r < out.grid.rows; ++r)
    for (int c = 0; c < out.grid.cols; ++c) {
      pixels.push_back(out.grid.pixel(r, c));
      inside.push_back(out.grid.inside(r, c));
    }
  const size_t n = pixels.size();

  double ta[kIntrinsicCount], tb[kIntrinsicCount];
  detail::cameraToVector(out.a.camera, ta);
  detail::cameraToVector(out.b.camera, tb);
  const DiffField diff = projectionDiff(ta, tb, out.a.camera, pixels, inside, options.fit_rotation);

  // Predicted covariance of the difference: J_a Sigma_a J_a^T + J_b Sigma_b J_b^T, the
  // Jacobians by central differences of the whole difference (rotation fit included).
  std::vector<Eigen::Matrix2d> C(n, Eigen::Matrix2d::Zero());
  for (int side = 0; side < 2; ++side) {
    const IntrinsicsResult& res = side == 0 ? out.a : out.b;
    std::vector<Eigen::MatrixXd> J(n, Eigen::MatrixXd::Zero(2, kIntrinsicCount));
    for (int k = 0; k < kIntrinsicCount; ++k) {
      if (!(res.sigma[k] > 0)) continue;
      const double step = 0.01 * res.sigma[k];
      double plus_a[kIntrinsicCount], minus_a[kIntrinsicCount], plus_b[kIntrinsicCount],
          minus_b[kIntrinsicCount];
      std::copy(ta, ta + kIntrinsicCount, plus_a);
      std::copy(ta, ta + kIntrinsicCount, minus_a);
      std::copy(tb, tb + kIntrinsicCount, plus_b);
      std::copy(tb, tb + kIntrinsicCount, minus_b);
      (side == 0 ? plus_a : plus_b)[k] += step;
      (side == 0 ? minus_a : minus_b)[k] -= step;
      const DiffField dp = projectionDiff(plus_a, plus_b, out.a.camera, pixels, inside, options.fit_rotation);
      const DiffField dm = projectionDiff(minus_a, minus_b, out.a.camera, pixels, inside, options.fit_rotation);
      for (size_t q = 0; q < n; ++q) {
        if (dp.valid[q] && dm.valid[q]) J[q].col(k) = (dp.d[q] - dm.d[q]) / (2 * step);
      }
    }
    for (size_t q = 0; q < n; ++q) C[q] += J[q] * res.covariance * J[q].transpose();
  }

  out.diff_px = cv::Mat(out.grid.rows, out.grid.cols, CV_64F, cv::Scalar(kNaN));
  out.predicted_px = out.diff_px.clone();
  out.normalised = out.diff_px.clone();
  double sum_d2 = 0, sum_m2 = 0, sum_p2 = 0;
  int count = 0, beyond = 0;
  for (size_t q = 0; q < n; ++q) {
    if (!diff.valid[q]) continue;
    const int r = static_cast<int>(q) / out.grid.cols, c = static_cast<int>(q) % out.grid.cols;
    const Eigen::Vector2d& d = diff.d[q];
    // A floor on the predicted covariance keeps a vanishing prediction (e.g. a point pinned
    // by the rotation fit) from turning rounding into a flag.
    const Eigen::Matrix2d Cq = C[q] + 1e-8 * Eigen::Matrix2d::Identity();
    const double m2 = d.dot(Cq.ldlt().solve(d));
    out.diff_px.at<double>(r, c) = d.norm();
    out.predicted_px.at<double>(r, c) = worstSigma(C[q]);
    out.normalised.at<double>(r, c) = std::sqrt(m2 / 2.0);
    sum_d2 += d.squaredNorm();
    sum_m2 += m2;
    sum_p2 += C[q].trace();
    out.diff_max_px = std::max(out.diff_max_px, d.norm());
    if (m2 > 11.83) ++beyond;
    ++count;
  }
  if (count > 0) {
    out.diff_rms_px = std::sqrt(sum_d2 / count);
    out.predicted_rms_px = std::sqrt(sum_p2 / count);
    out.normalised_rms = std::sqrt(sum_m2 / count / 2.0);
    out.fraction_beyond_3sigma = static_cast<double>(beyond) / count;
  }
  out.consistent = out.normalised_rms <= options.max_normalised_rms;
  return out;
}

std::string CrossValidationResult::report() const {
  std::ostringstream s;
  char line[256];
  s << "cross-validation: two halves of " << a.views_used << " and " << b.views_used << " views\n";
  std::snprintf(line, sizeof(line),
                "  half A: fx %.3f +- %.3f  cx %.3f +- %.3f  k1 %.5f  RMS %.4f px\n", a.camera.fx,
                a.sigma[0], a.camera.cx, a.sigma[2], a.camera.dist.k1, a.rms_px);
  s << line;
  std::snprintf(line, sizeof(line),
                "  half B: fx %.3f +- %.3f  cx %.3f +- %.3f  k1 %.5f  RMS %.4f px\n", b.camera.fx,
                b.sigma[0], b.camera.cx, b.sigma[2], b.camera.dist.k1, b.rms_px);
  s << line;
  std::snprintf(line, sizeof(line),
                "  projection difference: RMS %.4f px, max %.4f px; predicted RMS %.4f px\n",
                diff_rms_px, diff_max_px, predicted_rms_px);
  s << line;
  if (grid.data_radius_px > 0) {
    std::snprintf(line, sizeof(line), "  compared within %.0f px of the principal point (where the board was seen)\n",
                  grid.data_radius_px);
    s << line;
  }
  std::snprintf(line, sizeof(line),
                "  normalised RMS %.3f (1 = as predicted), %.1f %% of the grid beyond 3 sigma: %s\n",
                normalised_rms, 100.0 * fraction_beyond_3sigma,
                consistent ? "consistent" : "NOT consistent: the model or the data is wrong");
  s << line;
  return s.str();
}

}  // namespace previz::calib
