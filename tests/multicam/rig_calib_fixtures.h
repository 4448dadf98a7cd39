// Rig captures at the observation level for the rig solve's tests and benchmark: the studio
// rig's true cameras (datasets/rigs.h), the rig preset's board path, the board points each
// camera really sees (visibleBoardPoints through the empty stage), Gaussian pixel noise and
// optional outliers. No rendering, no detector: what the solver alone can do.
// Also the camera bump the image-level fixture and the tests share, and the error table.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "core/rig.h"
#include "datasets/random.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"
#include "multicam/observations.h"
#include "multicam/rig_calib.h"

namespace previz::multicam::testing {

// The knock a witness camera takes in the re-survey tests: its centre moves 3 cm and it turns
// 1 degree (T_world_cam' = T_world_cam * witnessBump(), as RigCaptureOptions::bump).
inline Pose witnessBump() {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(1.0 * M_PI / 180.0, Eigen::Vector3d(0.3, 1.0, 0.2).normalized())
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.02, -0.01, 0.02).normalized() * 0.03;
  return T;
}

struct ProjectedCaptureOptions {
  synth::StudioRigOptions rig;        // 8 witnesses 1280x720 + main 1920x1080
  int frames = 300;
  std::uint64_t board_seed = 1;       // board path (a new capture is a new seed)
  std::uint64_t noise_seed = 7;
  double noise_px = 0.2;              // per pixel coordinate
  double outlier_fraction = 0;        // detections replaced by a random pixel in the image
  bool floor = true;                  // the last floorBoardFrameCount(frames) frames
  bool floor_only = false;            // every frame shows the floor board (static witnesses)
  std::map<std::string, Pose> bump;   // camera -> T_world_cam' = T_world_cam * bump
};

struct ProjectedCapture {
  Rig truth;                          // bumps applied
  RigObservations obs;
};

inline ProjectedCapture projectedCapture(const ProjectedCaptureOptions& o) {
  ProjectedCapture out;
  out.truth = synth::studioRig(o.rig, synth::StudioConfig{}.take_duration_s, false);
  for (RigCamera& rc : out.truth.cameras) {
    const auto it = o.bump.find(rc.camera.name);
    if (it != o.bump.end()) rc.T_world_cam = rc.T_world_cam * it->second;
  }
  const BoardSpec board = synth::rigBoard(BoardType::kAprilGrid);
  RigObservations& obs = out.obs;
  obs.board = board;
  obs.frame_count = o.frames;
  obs.has_floor = o.floor || o.floor_only;
  obs.floor.board = board;
  obs.floor.T_world_board = synth::floorBoardPose();
  synth::StudioConfig config;
  config.seed = o.rig.seed;
  config.with_actor = false;
  config.with_prop = false;
  const synth::Studio studio(config);
  const synth::Scene stage = studio.sceneAt(0.0, synth::kLayerStage);
  for (const RigCamera& rc : out.truth.cameras) {
    CameraDetections d;
    d.camera = rc.camera.name;
    d.image_size = cv::Size(rc.camera.width, rc.camera.height);
    obs.cameras.push_back(d);
  }
  for (int f = 0; f < o.frames; ++f) {
    const bool floor = o.floor_only || (o.floor && synth::isFloorBoardFrame(f, o.frames));
    if (floor) obs.floor.frames.push_back(f);
    const Pose T_world_board = floor     ? synth::floorBoardPose()
                               : o.floor ? synth::rigBoardPose(board, f, o.frames, o.board_seed)
                                         : synth::rigWavedBoardPose(board, f, o.frames, o.board_seed);
    synth::Scene scene = stage;
    auto printed = synth::makeBoard(board, T_world_board);
    scene.add(floor ? synth::onTopOf(printed) : printed);
    for (size_t c = 0; c < out.truth.cameras.size(); ++c) {
      const RigCamera& rc = out.truth.cameras[c];
      std::vector<calib::Observation> points;
      for (const synth::BoardObservation& b :
           synth::visibleBoardPoints(rc.camera, rc.T_world_cam, board, T_world_board, scene)) {
        using synth::hashKey;
        const std::uint64_t key = hashKey(o.noise_seed, c, static_cast<std::uint64_t>(f), static_cast<std::uint64_t>(b.id));
        calib::Observation p;
        p.id = b.id;
        if (synth::unitFromBits(hashKey(key, 3)) < o.outlier_fraction) {
          p.px = Eigen::Vector2d(synth::unitFromBits(hashKey(key, 4)) * rc.camera.width - 0.5,
                                 synth::unitFromBits(hashKey(key, 5)) * rc.camera.height - 0.5);
        } else {
          p.px = b.px + o.noise_px * Eigen::Vector2d(synth::normalFromKey(hashKey(key, 1)),
                                                     synth::normalFromKey(hashKey(key, 2)));
        }
        points.push_back(p);
      }
      if (points.size() >= 4) obs.cameras[c].frames[f] = std::move(points);
    }
  }
  return out;
}

// The intrinsics of a rig with every pose reset, so that nothing of the true extrinsics can
// leak into a solve.
inline Rig intrinsicsOnly(const Rig& rig) {
  Rig out = rig;
  for (RigCamera& rc : out.cameras) rc.T_world_cam = Pose::Identity();
  return out;
}

// Error of one camera's estimated pose against the truth, and how many sigmas it is along the
// principal axes of the reported covariance (the largest over the three axes, rotation and
// position apart). Rotation error e in world axes: R_est = exp(e) R_true, as the covariance.
struct CameraError {
  std::string camera;
  double position_m = 0, rotation_deg = 0;
  double position_sigmas = 0, rotation_sigmas = 0;
  double sigma_position_m = 0, sigma_rotation_deg = 0;
  double rms_px = 0;
  // e^T C^-1 e over the 6 pose components (chi-square with 6 dof when the covariance is right);
  // -1 when the covariance is zero (a camera held as the gauge).
  double mahalanobis2 = -1;
};

inline double sigmasAlongAxes(const Eigen::Matrix3d& cov, const Eigen::Vector3d& e) {
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  double worst = 0;
  for (int k = 0; k < 3; ++k) {
    const double s = std::sqrt(std::max(eig.eigenvalues()(k), 1e-30));
    worst = std::max(worst, std::abs(eig.eigenvectors().col(k).dot(e)) / s);
  }
  return worst;
}

inline CameraError cameraError(const RigCamera& estimate, const CameraCalibReport& report,
                               const Pose& truth) {
  CameraError e;
  e.camera = estimate.camera.name;
  const Eigen::Vector3d dp = estimate.T_world_cam.translation() - truth.translation();
  const Eigen::AngleAxisd dr(estimate.T_world_cam.linear() * truth.linear().transpose());
  const Eigen::Vector3d rot = dr.axis() * dr.angle();
  e.position_m = dp.norm();
  e.rotation_deg = dr.angle() * 180.0 / M_PI;
  e.position_sigmas = sigmasAlongAxes(report.covariance.bottomRightCorner<3, 3>(), dp);
  e.rotation_sigmas = sigmasAlongAxes(report.covariance.topLeftCorner<3, 3>(), rot);
  e.sigma_position_m = report.sigma_position_m;
  e.sigma_rotation_deg = report.sigma_rotation_deg;
  e.rms_px = report.rms_px;
  if (report.covariance.norm() > 0) {
    Eigen::Matrix<double, 6, 1> err;
    err << rot, dp;
    e.mahalanobis2 = err.dot(report.covariance.ldlt().solve(err));
  }
  return e;
}

// Mean of mahalanobis2 / 6 over the cameras with a covariance: about 1 when the reported
// covariances are the real spread (neither too small nor too large); with n cameras its
// standard deviation is about sqrt(2 / (6 n)) (0.19 for 9 cameras).
inline double meanNormalizedError(const std::vector<CameraError>& errors) {
  double sum = 0;
  int n = 0;
  for (const CameraError& e : errors) {
    if (e.mahalanobis2 < 0) continue;
    sum += e.mahalanobis2 / 6.0;
    ++n;
  }
  return n > 0 ? sum / n : 0.0;
}

// One row per camera of a calibration against the truth (same camera order), printed.
inline std::vector<CameraError> rigErrors(const RigCalibResult& result, const Rig& truth,
                                          const char* title) {
  std::vector<CameraError> out;
  std::printf("  %s\n  camera      pos mm   rot deg   pos sig  rot sig   sigma mm  sigma deg   RMS px  views  rej\n", title);
  for (size_t c = 0; c < result.rig.cameras.size(); ++c) {
    const CameraError e =
        cameraError(result.rig.cameras[c], result.cameras[c], truth.at(result.rig.cameras[c].camera.name).T_world_cam);
    std::printf("  %-10s %7.3f  %8.5f  %7.2f  %7.2f  %9.4f  %9.5f  %7.4f  %5d %4d\n", e.camera.c_str(),
                e.position_m * 1e3, e.rotation_deg, e.position_sigmas, e.rotation_sigmas,
                e.sigma_position_m * 1e3, e.sigma_rotation_deg, e.rms_px, result.cameras[c].views,
                result.cameras[c].rejected);
    out.push_back(e);
  }
  std::printf("  residuals %d, rejected %d, RMS %.4f px, noise %.4f px, %d Ceres iterations, %.0f ms, "
              "mean e'C^-1e/6 %.2f\n",
              result.residuals, result.rejected, result.rms_px, result.sigma_px, result.ceres_iterations,
              result.solve_ms, meanNormalizedError(out));
  return out;
}

}  // namespace previz::multicam::testing
