// Board views of a rig capture and their single-view poses (multicam/detail/views.h). Lives at
// the folder root so the module's source glob picks it up.
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <unordered_map>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <omp.h>
#include <opencv2/calib3d.hpp>

#include "core/error.h"
#include "core/threads.h"
#include "multicam/detail/views.h"

namespace previz::multicam::detail {

namespace {

// Largest residual (px) a point may have against a view's pose to count as explained by it.
constexpr double kInlierPx = 3.0;

std::unordered_map<int, Eigen::Vector3d> pointMap(const BoardSpec& board) {
  std::unordered_map<int, Eigen::Vector3d> m;
  for (const BoardPoint& p : boardPoints(board)) m[p.id] = p.p_board;
  return m;
}

// Points spread over the board plane (a homography and a pose need more than a line).
bool spreadOverPlane(const std::vector<Eigen::Vector3d>& p) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& q : p) mean += q.head<2>();
  mean /= static_cast<double>(p.size());
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const auto& q : p) cov += (q.head<2>() - mean) * (q.head<2>() - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  return eig.eigenvalues()(0) > 1e-4 * eig.eigenvalues()(1);
}

}  // namespace

std::vector<double> viewResiduals(const Camera& camera, const View& view, const Pose& T_cam_board) {
  std::vector<double> r(view.ids.size(), 1e9);
  for (size_t i = 0; i < view.ids.size(); ++i) {
    const std::optional<Eigen::Vector2d> px = camera.project(T_cam_board * view.p_board[i]);
    if (px) r[i] = (*px - view.px[i]).norm();
  }
  return r;
}

bool robustViewPose(const Camera& camera, View& view, int min_points) {
  view.posed = false;
  if (static_cast<int>(view.ids.size()) < std::max(4, min_points) || !spreadOverPlane(view.p_board))
    return false;
  // Ideal normalized image coordinates: the homography and IPPE then need no distortion.
  const InverseDistortion inverse(camera.dist);
  std::vector<cv::Point2d> board_xy, ideal;
  std::vector<cv::Point3d> object;
  for (size_t i = 0; i < view.ids.size(); ++i) {
    const InverseResult x = inverse.solve(camera.pixelToNormalized(view.px[i]));
    if (!x.ok()) continue;
    board_xy.emplace_back(view.p_board[i].x(), view.p_board[i].y());
    object.emplace_back(view.p_board[i].x(), view.p_board[i].y(), 0.0);
    ideal.emplace_back(x.point.x(), x.point.y());
  }
  if (static_cast<int>(ideal.size()) < std::max(4, min_points)) return false;
  const double f = 0.5 * (camera.fx + camera.fy);
  try {
    cv::Mat mask;
    const cv::Mat H = cv::findHomography(board_xy, ideal, cv::RANSAC, kInlierPx / f, mask, 2000, 0.999);
    if (H.empty()) return false;
    std::vector<cv::Point3d> in_object;
    std::vector<cv::Point2d> in_ideal;
    for (size_t i = 0; i < ideal.size(); ++i) {
      if (mask.at<unsigned char>(static_cast<int>(i))) {
        in_object.push_back(object[i]);
        in_ideal.push_back(ideal[i]);
      }
    }
    if (static_cast<int>(in_object.size()) < std::max(4, min_points)) return false;
    const cv::Matx33d K = cv::Matx33d::eye();
    cv::Vec3d rvec, tvec;
    if (!cv::solvePnP(in_object, in_ideal, K, cv::noArray(), rvec, tvec, false, cv::SOLVEPNP_IPPE))
      return false;
    cv::solvePnP(in_object, in_ideal, K, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE);
    if (!(tvec[2] > 0)) return false;
    view.T_cam_board = poseFromRvecTvec(Eigen::Vector3d(rvec[0], rvec[1], rvec[2]),
                                        Eigen::Vector3d(tvec[0], tvec[1], tvec[2]));
  } catch (const cv::Exception&) {
    return false;
  }
  const std::vector<double> r = viewResiduals(camera, view, view.T_cam_board);
  view.inliers = static_cast<int>(std::count_if(r.begin(), r.end(), [](double e) { return e <= kInlierPx; }));
  view.posed = view.inliers >= std::max(4, min_points);
  return view.posed;
}

std::vector<std::map<int, View>> collectViews(const RigObservations& obs, const Rig& rig,
                                              int min_points, int threads) {
  const auto waved = pointMap(obs.board);
  const auto floor = obs.has_floor ? pointMap(obs.floor.board) : waved;
  std::vector<std::map<int, View>> views(rig.cameras.size());
  std::vector<View*> all;
  for (size_t c = 0; c < rig.cameras.size(); ++c) {
    const Camera& camera = rig.cameras[c].camera;
    const CameraDetections* det = obs.find(camera.name);
    if (det == nullptr) continue;
    if (det->image_size.width > 0 &&
        (det->image_size.width != camera.width || det->image_size.height != camera.height)) {
      ErrorContext context;
      context.camera = camera.name;
      throw Error("detections are " + std::to_string(det->image_size.width) + "x" +
                      std::to_string(det->image_size.height) + " px but the intrinsics are for " +
                      std::to_string(camera.width) + "x" + std::to_string(camera.height),
                  context);
    }
    for (const auto& [frame, points] : det->frames) {
      const auto& board = obs.isFloorFrame(frame) ? floor : waved;
      View v;
      v.camera = static_cast<int>(c);
      v.frame = frame;
      for (const calib::Observation& o : points) {
        const auto it = board.find(o.id);
        if (it == board.end()) {
          ErrorContext context;
          context.camera = camera.name;
          context.frame = frame;
          throw Error("point id " + std::to_string(o.id) + " is not on the " +
                          (obs.isFloorFrame(frame) ? "floor board" : "board") + " (wrong board spec?)",
                      context);
        }
        if (!o.px.allFinite()) continue;
        if (std::find(v.ids.begin(), v.ids.end(), o.id) != v.ids.end()) continue;
        v.ids.push_back(o.id);
        v.p_board.push_back(it->second);
        v.px.push_back(o.px);
      }
      if (static_cast<int>(v.ids.size()) >= min_points) views[c].emplace(frame, std::move(v));
    }
  }
  for (auto& per_camera : views)
    for (auto& [frame, v] : per_camera) all.push_back(&v);
  // Views are independent; robustViewPose does not throw (OpenCV exceptions caught inside).
#pragma omp parallel for schedule(dynamic, 4) num_threads(resolveThreads(threads))
  for (int k = 0; k < static_cast<int>(all.size()); ++k) {
    robustViewPose(rig.cameras[all[k]->camera].camera, *all[k], min_points);
  }
  return views;
}

PoseMean robustMeanPose(const std::vector<Pose>& samples, double length_m, double floor_m) {
  PoseMean out;
  out.samples = static_cast<int>(samples.size());
  if (samples.empty()) return out;
  const size_t n = samples.size();
  std::vector<Eigen::Quaterniond> q(n);
  for (size_t i = 0; i < n; ++i) q[i] = Eigen::Quaterniond(samples[i].linear()).normalized();
  auto distance = [&](size_t i, size_t j) {
    const double dot = std::min(1.0, std::abs(q[i].dot(q[j])));
    return (samples[i].translation() - samples[j].translation()).norm() + length_m * 2.0 * std::acos(dot);
  };
  // Medoid; samples above a few hundred are thinned for it (the medoid only seeds the mean).
  const size_t stride = std::max<size_t>(1, n / 200);
  size_t best = 0;
  double best_cost = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < n; i += stride) {
    double cost = 0;
    for (size_t j = 0; j < n; j += stride) cost += std::min(distance(i, j), 1.0);
    if (cost < best_cost) {
      best_cost = cost;
      best = i;
    }
  }
  std::vector<double> d(n);
  for (size_t i = 0; i < n; ++i) d[i] = distance(best, i);
  std::vector<double> sorted = d;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  const double threshold = std::max(3.0 * sorted[n / 2], floor_m);
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector4d qsum = Eigen::Vector4d::Zero();
  for (size_t i = 0; i < n; ++i) {
    if (d[i] > threshold) continue;
    ++out.inliers;
    t += samples[i].translation();
    const double sign = q[i].dot(q[best]) < 0 ? -1.0 : 1.0;
    qsum += sign * q[i].coeffs();
  }
  out.mean = Pose::Identity();
  out.mean.linear() = Eigen::Quaterniond(qsum.normalized()).toRotationMatrix();
  out.mean.translation() = t / out.inliers;
  std::vector<double> dt, dr;
  for (size_t i = 0; i < n; ++i) {
    if (d[i] > threshold) continue;
    dt.push_back(translationDistance(samples[i], out.mean));
    dr.push_back(rotationDistance(samples[i], out.mean));
  }
  std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
  std::nth_element(dr.begin(), dr.begin() + dr.size() / 2, dr.end());
  out.spread_m = dt[dt.size() / 2];
  out.spread_rad = dr[dr.size() / 2];
  return out;
}

}  // namespace previz::multicam::detail
