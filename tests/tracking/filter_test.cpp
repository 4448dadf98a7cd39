// Issue 6 item 2. Jitter: the studio's crate standing still, 8 witnesses rendered once without
// noise; every frame draws fresh noise (sigma = 2 grey levels) over the crate's window and
// PropTracker detects (ROI after the first frame), solves and filters: std over 100 frames of the
// filtered pose <= 0.3 mm and 0.05 degrees. Lag: a 1 m/s move (with a 1 rad/s turn) from
// projected tag corners plus Gaussian corner noise (rendering 100 moving frames x 8 cameras is
// too slow for a test): the filtered pose trails the truth by at most one frame's travel.
#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "core/error.h"
#include "studio_fixture.h"
#include "tracking/filter.h"
#include "tracking/solve.h"
#include "tracking/tracker.h"

namespace previz::tracking {
namespace {

constexpr double kFps = 24.0;  // the studio's frame rate

struct Spread {
  double position_m = 0, rotation_rad = 0;
};
// RMS distance of the poses from their mean position / rotation (3-D, not per axis).
Spread spread(const std::vector<Pose>& poses) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Pose& p : poses) mean += p.translation();
  mean /= static_cast<double>(poses.size());
  Eigen::Vector3d w_mean = Eigen::Vector3d::Zero();
  const Eigen::Matrix3d R0 = poses[0].linear();
  for (const Pose& p : poses) {
    const Eigen::AngleAxisd aa(p.linear() * R0.transpose());
    w_mean += aa.angle() * aa.axis();
  }
  w_mean /= static_cast<double>(poses.size());
  double sp = 0, sr = 0;
  for (const Pose& p : poses) {
    sp += (p.translation() - mean).squaredNorm();
    const Eigen::AngleAxisd aa(p.linear() * R0.transpose());
    sr += (aa.angle() * aa.axis() - w_mean).squaredNorm();
  }
  return {std::sqrt(sp / poses.size()), std::sqrt(sr / poses.size())};
}

TEST(TrackingFilter, StaticPropJitterBelowPointThreeMillimetresAndPointZeroFiveDegrees) {
  test::StudioFixture fx(std::filesystem::path(PREVIZ_TEST_TMP) / "tracking_stage_cache");
  const double t = 3.0;
  const Pose T = fx.studio.T_world_prop(t);
  const synth::Scene scene = fx.studio.sceneAt(t, synth::kLayersPlate);
  std::vector<cv::Mat> clean(static_cast<size_t>(fx.cameras()));
  std::vector<cv::Rect> windows(clean.size());
  test::parallelFor(fx.cameras(), [&](int c) {
    clean[static_cast<size_t>(c)] = fx.renderWith(c, scene, T, 0, true);
    windows[static_cast<size_t>(c)] = fx.propWindow(c, T);
  });
  TrackerOptions o;
  o.threads = 2;
  PropTracker tracker(fx.rig.cameras, test::studioProps(fx.studio), o);
  std::vector<Pose> filtered, raw;
  int full = 0;
  constexpr int kWarmup = 10, kFrames = 100;
  for (int f = 0; f < kWarmup + kFrames; ++f) {
    std::vector<cv::Mat> images(clean.size());
    for (size_t c = 0; c < clean.size(); ++c) {
      images[c] = clean[c].clone();
      fx.addNoise(images[c], windows[c], 1000003ULL * f + c);
    }
    const TrackFrame r = tracker.track(f, f / kFps, images);
    ASSERT_TRUE(r.props[0].tracked) << "frame " << f << ": " << r.props[0].measured.failure;
    full += r.full_frame ? 1 : 0;
    if (f < kWarmup) continue;
    filtered.push_back(r.props[0].T_world_prop);
    raw.push_back(r.props[0].measured.T);
  }
  const Spread sf = spread(filtered), sr = spread(raw);
  double bias = 0;
  for (const Pose& p : filtered) bias += translationDistance(p, T) / filtered.size();
  std::printf("jitter: raw %.3f mm %.4f deg -> filtered %.3f mm %.4f deg (RMS over %d frames after %d warm-up; "
              "%d full-frame searches; mean error vs truth %.3f mm)\n",
              1e3 * sr.position_m, sr.rotation_rad * 180 / M_PI, 1e3 * sf.position_m, sf.rotation_rad * 180 / M_PI,
              kFrames, kWarmup, full, 1e3 * bias);
  EXPECT_LE(1e3 * sf.position_m, 0.3);
  EXPECT_LE(sf.rotation_rad * 180 / M_PI, 0.05);
  EXPECT_LT(sf.position_m, sr.position_m);  // the filter does something
  EXPECT_LT(bias, 0.002);
}

// Tag observations of the crate at T from every camera that faces a tag, corners projected with
// the true lens plus N(0, sigma_px).
std::vector<TagObservation> observe(const test::StudioFixture& fx, const PropDef& prop, const Pose& T,
                                    double sigma_px, std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, sigma_px);
  std::vector<TagObservation> out;
  for (int c = 0; c < fx.cameras(); ++c) {
    const RigCamera& rc = fx.rig.cameras[static_cast<size_t>(c)];
    const Pose T_cam_prop = rc.T_world_cam.inverse() * T;
    for (size_t k = 0; k < prop.tags.size(); ++k) {
      const TagDef& tag = prop.tags[k];
      const Pose T_cam_tag = T_cam_prop * tag.T_prop_tag;
      // Visible face: the tag's z (into the face) points away from the camera, and not grazing.
      if (T_cam_tag.linear().col(2).dot(T_cam_tag.translation().normalized()) < 0.3) continue;
      std::array<Eigen::Vector2d, 4> px;
      bool ok = true;
      for (int q = 0; q < 4; ++q) {
        const auto p = rc.camera.project(T_cam_prop * tag.cornersInProp()[q]);
        ok = ok && p && rc.camera.inImage(*p, 4);
        if (p) px[q] = *p + Eigen::Vector2d(n(rng), n(rng));
      }
      if (ok) out.push_back(makeTagObservation(rc.camera, c, static_cast<int>(k), px));
    }
  }
  return out;
}

TEST(TrackingFilter, LagOnOneMetrePerSecondMoveAtMostOneFrame) {
  const test::StudioFixture fx;
  const PropDef prop = test::studioProps(fx.studio).props[0];
  const Pose start = fx.studio.T_world_prop(3.0);
  const Eigen::Vector3d dir = Eigen::Vector3d(1, 0.3, 0).normalized();
  const double speed = 1.0, turn = 1.0;  // m/s, rad/s (about world z)
  // At rest 1 s, a 2-frame ramp to full speed, 1.5 s at speed, a 2-frame stop, 1 s at rest.
  auto distanceAt = [&](double t) {
    const double t0 = 1.0, ramp = 2 / kFps, t1 = t0 + ramp + 1.5, t2 = t1 + ramp;
    if (t <= t0) return 0.0;
    if (t <= t0 + ramp) return 0.5 * (t - t0) * (t - t0) / ramp;
    if (t <= t1) return 0.5 * ramp + (t - t0 - ramp);
    if (t <= t2) return 0.5 * ramp + (t1 - t0 - ramp) + (t - t1) - 0.5 * (t - t1) * (t - t1) / ramp;
    return 0.5 * ramp + (t1 - t0 - ramp) + 0.5 * ramp;
  };
  auto truthAt = [&](double t) {
    const double d = distanceAt(t);
    Pose T = start;
    T.translation() += speed * d * dir;
    T.linear() = Eigen::AngleAxisd(turn * d, Eigen::Vector3d::UnitZ()).toRotationMatrix() * start.linear();
    return T;
  };
  std::mt19937 rng(7);
  PoseFilter filter;
  const double sigma_px = 0.1;
  double worst_lag = 0, worst_rot_lag = 0, sum_lag = 0;
  int moving = 0;
  std::vector<Pose> rest, rest_raw;
  for (int f = 0; f < static_cast<int>(4.0 * kFps); ++f) {
    const double t = f / kFps;
    const Pose truth = truthAt(t);
    const PoseEstimate e = solvePropPose(fx.rig.cameras, prop, observe(fx, prop, truth, sigma_px, rng), SolveOptions{});
    ASSERT_TRUE(e.ok) << "frame " << f;
    const Pose out = filter.update(t, e.T, e.covariance);
    // Travel of one frame at this moment (the truth's own speed).
    const double step = (truthAt(t).translation() - truthAt(t - 1 / kFps).translation()).norm();
    if (step > 0.5 * speed / kFps) {
      const Eigen::Vector3d v = (truthAt(t).translation() - truthAt(t - 1 / kFps).translation()).normalized();
      const double trailing = (truth.translation() - out.translation()).dot(v);
      const double lag_frames = trailing / (speed / kFps);
      const double rot_lag = rotationDistance(truth, out) / (turn * speed / kFps);
      worst_lag = std::max(worst_lag, std::abs(lag_frames));
      worst_rot_lag = std::max(worst_rot_lag, rot_lag);
      sum_lag += lag_frames;
      ++moving;
    } else if (t > 3.3) {
      rest.push_back(out);
      rest_raw.push_back(e.T);
    }
  }
  ASSERT_GT(moving, 30);
  const Spread s = spread(rest), s_raw = spread(rest_raw);
  std::printf("lag: 1 m/s + 1 rad/s move at %.0f fps, corner noise %.2f px: worst %.3f frames (position), %.3f frames "
              "(rotation), mean %.3f frames over %d moving frames; at rest after the stop raw %.3f mm %.4f deg -> filtered %.3f mm %.4f deg\n",
              kFps, sigma_px, worst_lag, worst_rot_lag, sum_lag / moving, moving, 1e3 * s_raw.position_m, s_raw.rotation_rad * 180 / M_PI, 1e3 * s.position_m,
              s.rotation_rad * 180 / M_PI);
  EXPECT_LE(worst_lag, 1.0);
  EXPECT_LE(worst_rot_lag, 1.0);
  // Back at rest the filter smooths again.
  EXPECT_LT(s.position_m, s_raw.position_m);
  EXPECT_LT(s.rotation_rad, s_raw.rotation_rad);
}

TEST(TrackingFilter, OptionsAreValidated) {
  FilterOptions o;
  o.accel_sigma_mps2 = 0;
  EXPECT_THROW(PoseFilter{o}, Error);
  o = {};
  o.gate_sigma = -1;
  EXPECT_THROW(PoseFilter{o}, Error);
}

}  // namespace
}  // namespace previz::tracking
