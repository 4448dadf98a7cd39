// Hand–eye and delay of the camera tracker from a board take (live/tracker_align.h).
#include "live/tracker_align.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/error.h"
#include "core/stopwatch.h"
#include "core/units.h"

namespace previz::live {

namespace {

// A view's corners as ideal normalized coordinates (the known lens's distortion taken out).
struct NormView {
  double time_s;
  std::vector<Eigen::Vector3d> X;
  std::vector<Eigen::Vector2d> x;
};

// The samples as the cost functions read them: arrival times, positions, rotations and the
// rotation vector from each sample to the next (for slerp: R_i exp(s w_i)).
struct Track {
  std::vector<double> a;
  std::vector<Eigen::Vector3d> p;
  std::vector<Eigen::Matrix3d> R;
  std::vector<Eigen::Vector3d> w;
  // The bracket [i, i+1] holding arrival t (clamped to the ends: extrapolates linearly).
  int bracket(double t) const {
    const auto it = std::upper_bound(a.begin(), a.end(), t);
    int i = static_cast<int>(it - a.begin()) - 1;
    return std::clamp(i, 0, static_cast<int>(a.size()) - 2);
  }
  bool covers(double t) const { return t >= a.front() && t <= a.back(); }
};

template <typename T>
void poseFromParams(const T* aa, const T* t, const T* X, T* out) {
  T r[3];
  ceres::AngleAxisRotatePoint(aa, X, r);
  out[0] = r[0] + t[0];
  out[1] = r[1] + t[1];
  out[2] = r[2] + t[2];
}

template <typename T>
void inversePose(const T* aa, const T* t, const T* X, T* out) {  // R^T (X - t)
  const T d[3] = {X[0] - t[0], X[1] - t[1], X[2] - t[2]};
  const T minus[3] = {-aa[0], -aa[1], -aa[2]};
  ceres::AngleAxisRotatePoint(minus, d, out);
}

struct CornerCost {
  CornerCost(const Track* track, double time_s, const Eigen::Vector3d& X, const Eigen::Vector2d& x, double fx, double fy)
      : track_(track), time_s_(time_s), X_(X), x_(x), fx_(fx), fy_(fy) {}

  template <typename T>
  bool operator()(const T* tc_aa, const T* tc_t, const T* sb_aa, const T* sb_t, const T* delay, T* res) const {
    // The tracked body at arrival time t_f + delay: slerp / lerp between the bracketing samples.
    const double t_value = time_s_ + scalar(delay[0]);
    const int i = track_->bracket(t_value);
    const T s = (T(time_s_) + delay[0] - T(track_->a[i])) / T(track_->a[i + 1] - track_->a[i]);
    T p_st[3];
    for (int k = 0; k < 3; ++k) p_st[k] = (T(1) - s) * T(track_->p[i][k]) + s * T(track_->p[i + 1][k]);
    // R_st = R_i exp(s w_i): X_tracker = exp(s w)^T R_i^T (X_stage - p).
    const T sw_minus[3] = {-s * T(track_->w[i][0]), -s * T(track_->w[i][1]), -s * T(track_->w[i][2])};
    const T Xb[3] = {T(X_[0]), T(X_[1]), T(X_[2])};
    T Xs[3], d[3], Xi[3], Xt[3], Xc[3];
    poseFromParams(sb_aa, sb_t, Xb, Xs);
    for (int k = 0; k < 3; ++k) d[k] = Xs[k] - p_st[k];
    const Eigen::Matrix3d& Ri = track_->R[i];
    for (int r = 0; r < 3; ++r) Xi[r] = T(Ri(0, r)) * d[0] + T(Ri(1, r)) * d[1] + T(Ri(2, r)) * d[2];
    ceres::AngleAxisRotatePoint(sw_minus, Xi, Xt);
    inversePose(tc_aa, tc_t, Xt, Xc);
    if (!(scalar(Xc[2]) > 1e-6)) return false;
    res[0] = T(fx_) * (Xc[0] / Xc[2] - T(x_[0]));
    res[1] = T(fy_) * (Xc[1] / Xc[2] - T(x_[1]));
    return true;
  }

  static double scalar(double v) { return v; }
  template <int N>
  static double scalar(const ceres::Jet<double, N>& v) {
    return v.a;
  }

  const Track* track_;
  double time_s_;
  Eigen::Vector3d X_;
  Eigen::Vector2d x_;
  double fx_, fy_;
};

Pose paramsToPose(const double* aa, const double* t) {
  Eigen::Matrix3d R;
  double Rm[9];
  ceres::AngleAxisToRotationMatrix(aa, ceres::ColumnMajorAdapter3x3(Rm));
  R = Eigen::Map<const Eigen::Matrix3d>(Rm);
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
  return T;
}

void poseToParams(const Pose& T, double* aa, double* t) {
  const Eigen::Matrix3d R = T.linear();
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(R.data()), aa);
  for (int k = 0; k < 3; ++k) t[k] = T.translation()[k];
}

Pose trackAt(const Track& tr, double t) {
  const int i = tr.bracket(t);
  const double s = (t - tr.a[i]) / (tr.a[i + 1] - tr.a[i]);
  Pose T = Pose::Identity();
  T.linear() = tr.R[i] * Eigen::AngleAxisd(s * tr.w[i].norm(), tr.w[i].norm() > 0 ? tr.w[i].normalized() : Eigen::Vector3d::UnitX())
                             .toRotationMatrix();
  T.translation() = (1 - s) * tr.p[i] + s * tr.p[i + 1];
  return T;
}

struct Params {
  double tc_aa[3] = {0, 0, 0}, tc_t[3] = {0, 0, 0}, sb_aa[3] = {0, 0, 0}, sb_t[3] = {0, 0, 0}, delay = 0;
};

struct SolveOut {
  double rms_px = 0;
  int iterations = 0;
  bool usable = false;
};

SolveOut solve(const std::vector<NormView>& views, const Track& track, const Camera& cam, Params& p, bool delay_free,
               int max_iterations, double huber_px, int view_step, ceres::Problem** keep = nullptr) {
  ceres::Problem::Options po;
  auto* problem = new ceres::Problem(po);
  int residuals = 0;
  for (size_t v = 0; v < views.size(); v += view_step) {
    if (!track.covers(views[v].time_s + p.delay)) continue;
    for (size_t k = 0; k < views[v].X.size(); ++k) {
      auto* cost = new ceres::AutoDiffCostFunction<CornerCost, 2, 3, 3, 3, 3, 1>(
          new CornerCost(&track, views[v].time_s, views[v].X[k], views[v].x[k], cam.fx, cam.fy));
      problem->AddResidualBlock(cost, new ceres::HuberLoss(huber_px), p.tc_aa, p.tc_t, p.sb_aa, p.sb_t, &p.delay);
      ++residuals;
    }
  }
  SolveOut out;
  if (residuals < 20) {
    delete problem;
    return out;
  }
  if (!delay_free) problem->SetParameterBlockConstant(&p.delay);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = max_iterations;
  so.num_threads = 1;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  ceres::Solver::Summary summary;
  ceres::Solve(so, problem, &summary);
  // RMS of the plain (not robustified) pixel residuals.
  double sum = 0;
  std::vector<double> r;
  ceres::Problem::EvaluateOptions eo;
  eo.apply_loss_function = false;
  problem->Evaluate(eo, nullptr, &r, nullptr, nullptr);
  for (double x : r) sum += x * x;
  out.rms_px = std::sqrt(sum / std::max<size_t>(1, r.size() / 2));
  out.iterations = static_cast<int>(summary.iterations.size());
  out.usable = summary.IsSolutionUsable();
  if (keep) *keep = problem;
  else delete problem;
  return out;
}

}  // namespace

void TrackerAlignOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    throw Error("tracker align: " + field + " " + what, fieldContext(field));
  };
  if (!(delay_search_s >= 0 && delay_search_s <= 2)) bad("delay_search_s", "must be within [0, 2] s");
  if (!(delay_step_s > 0 && delay_step_s <= 0.1)) bad("delay_step_s", "must be within (0, 0.1] s");
  if (!(huber_px > 0)) bad("huber_px", "must be > 0");
  if (max_iterations < 1) bad("max_iterations", "must be >= 1");
  if (min_points < 4) bad("min_points", "must be >= 4");
}

TrackerAlignResult alignTracker(const std::vector<BoardView>& views, const Camera& cam,
                                const std::vector<AlignSample>& samples, const TrackerAlignOptions& o) {
  o.validate();
  const Stopwatch t_start;
  if (samples.size() < 2) throw Error("tracker align: fewer than 2 tracker samples", fieldContext("--tracker-log"));
  Track track;
  for (const AlignSample& s : samples) {
    if (!track.a.empty() && s.arrival_s <= track.a.back()) continue;  // arrival order, no repeats
    track.a.push_back(s.arrival_s);
    track.p.push_back(s.T_stage_tracker.translation());
    track.R.push_back(s.T_stage_tracker.linear());
  }
  if (track.a.size() < 2) throw Error("tracker align: fewer than 2 distinct tracker samples", fieldContext("--tracker-log"));
  TrackerAlignResult result;
  if (o.regular_rate && track.a.size() >= 8) {
    // Sample numbers at the median period (a lost sample leaves its number unused), then the
    // least-squares line through (number, arrival).
    std::vector<double> d;
    for (size_t i = 0; i + 1 < track.a.size(); ++i) d.push_back(track.a[i + 1] - track.a[i]);
    std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
    const double period = d[d.size() / 2];
    if (period > 0) {
      std::vector<double> k(track.a.size());
      k[0] = 0;
      for (size_t i = 1; i < k.size(); ++i)
        k[i] = k[i - 1] + std::max(1.0, std::round((track.a[i] - track.a[i - 1]) / period));
      double sk = 0, sa = 0, skk = 0, ska = 0;
      const double n = static_cast<double>(k.size());
      for (size_t i = 0; i < k.size(); ++i) {
        sk += k[i];
        sa += track.a[i];
        skk += k[i] * k[i];
        ska += k[i] * track.a[i];
      }
      const double b = (n * ska - sk * sa) / (n * skk - sk * sk), a0 = (sa - b * sk) / n;
      double ss = 0;
      for (size_t i = 0; i < k.size(); ++i) {
        const double fit = a0 + b * k[i];
        ss += (track.a[i] - fit) * (track.a[i] - fit);
        track.a[i] = fit;
      }
      result.arrival_jitter_ms = 1e3 * std::sqrt(ss / n);
      result.sample_period_s = b;
    }
  }
  for (size_t i = 0; i + 1 < track.a.size(); ++i) {
    const Eigen::AngleAxisd aa(track.R[i].transpose() * track.R[i + 1]);
    track.w.push_back(aa.angle() * aa.axis());
  }
  track.w.push_back(Eigen::Vector3d::Zero());

  std::vector<NormView> norm;
  std::vector<Pose> pnp;  // T_cam_board per view, for the start
  for (const BoardView& v : views) {
    NormView n;
    n.time_s = v.time_s;
    for (size_t k = 0; k < v.pixels.size() && k < v.board_points.size(); ++k) {
      const std::optional<Eigen::Vector3d> ray = cam.unproject(v.pixels[k]);
      if (!ray || (*ray)[2] <= 0) continue;
      n.X.push_back(v.board_points[k]);
      n.x.push_back(ray->head<2>() / (*ray)[2]);
    }
    if (static_cast<int>(n.X.size()) < o.min_points) {
      ++result.views_dropped;
      continue;
    }
    std::vector<cv::Point3d> obj;
    std::vector<cv::Point2d> img;
    for (size_t k = 0; k < n.X.size(); ++k) {
      obj.emplace_back(n.X[k].x(), n.X[k].y(), n.X[k].z());
      img.emplace_back(n.x[k].x(), n.x[k].y());
    }
    cv::Mat rvec, tvec;
    if (!cv::solvePnP(obj, img, cv::Mat::eye(3, 3, CV_64F), cv::Mat(), rvec, tvec, false, cv::SOLVEPNP_ITERATIVE)) {
      ++result.views_dropped;
      continue;
    }
    pnp.push_back(poseFromRvecTvec(Eigen::Vector3d(rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2)),
                                   Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2))));
    norm.push_back(std::move(n));
  }
  if (norm.size() < 3) throw Error("tracker align: fewer than 3 views of the board with " + std::to_string(o.min_points) +
                                       "+ corners", fieldContext("--board"));

  // The delay on a grid: at each candidate the offsets solved with it held (warm-started from
  // the previous candidate, every 4th view), keeping the one with the lowest RMS.
  Params best;
  double best_rms = 1e300;
  Params p;
  bool started = false;
  for (double d = -o.delay_search_s; d <= o.delay_search_s + 1e-12; d += o.delay_step_s) {
    // Views whose instant + d has samples around it.
    size_t first = 0;
    while (first < norm.size() && !track.covers(norm[first].time_s + d)) ++first;
    if (first == norm.size()) continue;
    p.delay = d;
    if (!started) {
      // Start: the lens at the tracked body (T_tracker_cam = I), the board where the first view
      // puts it.
      const Pose T_sb = trackAt(track, norm[first].time_s + d) * pnp[first];
      poseToParams(Pose::Identity(), p.tc_aa, p.tc_t);
      poseToParams(T_sb, p.sb_aa, p.sb_t);
      started = true;
    }
    const SolveOut s = solve(norm, track, cam, p, false, 25, o.huber_px, 4);
    if (!s.usable) continue;
    result.delay_grid.push_back({d, s.rms_px});
    if (s.rms_px < best_rms) {
      best_rms = s.rms_px;
      best = p;
    }
  }
  if (best_rms == 1e300) throw Error("tracker align: no delay in the search range gives a solution", fieldContext("--tracker-log"));

  // Everything together, every view.
  ceres::Problem* problem = nullptr;
  p = best;
  const SolveOut s = solve(norm, track, cam, p, true, o.max_iterations, o.huber_px, 1, &problem);
  if (!s.usable || !problem) {
    delete problem;
    throw Error("tracker align: the joint solve failed", fieldContext("--tracker-log"));
  }
  result.T_tracker_cam = paramsToPose(p.tc_aa, p.tc_t);
  result.T_stage_board = paramsToPose(p.sb_aa, p.sb_t);
  result.delay_s = p.delay;
  result.rms_px = s.rms_px;
  result.iterations = s.iterations;
  result.views = static_cast<int>(norm.size());
  for (const NormView& v : norm) result.points += static_cast<int>(v.X.size());

  // 1σ from the covariance of (T_tracker_cam, delay), scaled by the residuals' variance.
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> blocks = {
      {p.tc_aa, p.tc_aa}, {p.tc_t, p.tc_t}, {&p.delay, &p.delay}};
  if (cov.Compute(blocks, problem)) {
    const int dof = std::max(1, 2 * result.points - 13);
    const double var = s.rms_px * s.rms_px * 2.0 * result.points / dof;
    double caa[9], ct[9], cd;
    cov.GetCovarianceBlock(p.tc_aa, p.tc_aa, caa);
    cov.GetCovarianceBlock(p.tc_t, p.tc_t, ct);
    cov.GetCovarianceBlock(&p.delay, &p.delay, &cd);
    // The position of the lens in the tracker frame is tc_t itself.
    const Eigen::Matrix3d Caa = Eigen::Map<Eigen::Matrix3d>(caa) * var, Ct = Eigen::Map<Eigen::Matrix3d>(ct) * var;
    result.sigma_rotation_rad = std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(Caa).eigenvalues().maxCoeff()));
    result.sigma_position_m = std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(Ct).eigenvalues().maxCoeff()));
    result.sigma_delay_s = std::sqrt(std::max(0.0, cd * var));
    result.covariance_ok = true;
  }
  delete problem;
  result.solve_ms = t_start.ms();
  return result;
}

std::string TrackerAlignResult::fullReport() const {
  std::ostringstream s;
  const Eigen::AngleAxisd aa(T_tracker_cam.linear());
  char line[768];
  std::snprintf(line, sizeof(line),
                "tracker align: %d views (%d dropped), %d corners, RMS %.3f px, %d iterations, %.0f ms\n"
                "  T_tracker_cam: lens at (%.2f, %.2f, %.2f) mm in the tracker frame (%.2f mm away), rotated %.3f deg; "
                "1 sigma %.3f mm, %.4f deg%s\n"
                "  delay: %.2f ms (1 sigma %.3f ms): samples arrive this long after their instant; arrivals %.3f ms RMS "
                "about a %.3f ms period (taken out)\n",
                views, views_dropped, points, rms_px, iterations, solve_ms, 1e3 * T_tracker_cam.translation().x(),
                1e3 * T_tracker_cam.translation().y(), 1e3 * T_tracker_cam.translation().z(),
                1e3 * T_tracker_cam.translation().norm(), degrees(aa.angle()), 1e3 * sigma_position_m,
                degrees(sigma_rotation_rad), covariance_ok ? "" : " (covariance not available)", 1e3 * delay_s,
                1e3 * sigma_delay_s, arrival_jitter_ms, 1e3 * sample_period_s);
  s << line;
  return s.str();
}

nlohmann::json TrackerAlignResult::toJson() const {
  nlohmann::json grid = nlohmann::json::array();
  for (const auto& [d, r] : delay_grid) grid.push_back({d, r});
  return {{"T_tracker_cam", poseToJson(T_tracker_cam)},
          {"T_stage_board", poseToJson(T_stage_board)},
          {"delay_s", delay_s},
          {"sigma_position_m", sigma_position_m},
          {"sigma_rotation_deg", degrees(sigma_rotation_rad)},
          {"sigma_delay_s", sigma_delay_s},
          {"covariance_ok", covariance_ok},
          {"rms_px", rms_px},
          {"views", views},
          {"views_dropped", views_dropped},
          {"points", points},
          {"iterations", iterations},
          {"solve_ms", solve_ms},
          {"arrival_jitter_ms", arrival_jitter_ms},
          {"sample_period_s", sample_period_s},
          {"delay_grid", grid}};
}

}  // namespace previz::live
