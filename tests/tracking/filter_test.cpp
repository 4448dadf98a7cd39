// Issue 6 item 2. Jitter: the studio's crate standing still, 8 witnesses rendered once without
// noise; every frame draws fresh noise (sigma = 2 grey levels) over the crate's window and
// PropTracker detects (ROI after the first frame), solves and filters: std over 100 frames of the
// filtered pose <= 0.3 mm and 0.05 degrees. Lag: a 1 m/s move (with a 1 rad/s turn) from
// projected tag corners plus Gaussian corner noise (rendering 100 moving frames x 8 cameras is
// too slow for a test): the filtered pose trails the truth by at most one frame's travel.
// Issue 33 item 4: a prop turning 10 deg/frame is followed within the per-frame sigma, and a still
// prop is as steady as before (generated poses, filter_motion.h; figures below each test).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "filter_motion.h"
#include "studio_fixture.h"
#include "tracking/filter.h"
#include "tracking/solve.h"
#include "tracking/tracker.h"

namespace previz::tracking {
namespace {

constexpr double kFps = 24.0;  // the studio's frame rate

using test::Spread;
Spread spread(const std::vector<Pose>& poses) { return test::poseSpread(poses); }

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

// Per-frame sigmas of the joint solve (per axis, as the filter is given them): the studio's crate
// seen by the witnesses (docs/formats.md's track output: 0.16 mm worst axis, 0.05 deg; taken at
// 0.3 mm), and a small prop with one tag in view (ten times less certain in rotation, three in
// position).
struct SigmaLevel {
  const char* name;
  double rotation_rad, position_m;
};
const SigmaLevel kSigmaLevels[] = {{"crate", 0.05 * M_PI / 180, 0.3e-3}, {"one tag", 0.5 * M_PI / 180, 1.0e-3}};

void printFollow(const char* who, const test::FollowFigures& f, const SigmaLevel& l) {
  const double deg = l.rotation_rad * 180 / M_PI, mm = 1e3 * l.position_m;
  std::printf("    %-8s lag %.2f sigma = %.4f deg, %.2f sigma = %.4f mm; 3-D error median %.2f / %.2f sigma, max %.2f "
              "sigma = %.4f deg / %.2f sigma = %.4f mm\n",
              who, f.lag_rotation, f.lag_rotation * deg, f.lag_position, f.lag_position * mm, f.median_rotation,
              f.median_position, f.max_rotation, f.max_rotation * deg, f.max_position, f.max_position * mm);
}

// Issue 33 item 4: "a tag yawing 10 deg a frame differs from its per-frame solve by up to 7 deg and
// 2.9 mm after filtering". Generated poses (filter_motion.h), 50 runs of each motion at 24 fps: a
// yaw of 10 deg/frame starting and stopping at once or over 4-frame ramps, about an axis through
// the prop origin or 10 cm from it (a prop turned in the hand), and the 1 m/s glide above. Scored
// from the spin-up on, leaving out the first 2 frames after the start and after the stop. Truth and
// tolerances, in units of the per-frame sigma (per axis):
// - lag (the error averaged over the runs, worst frame, 3-D) <= 1 sigma, in rotation and position;
// - the filter still filters while following: the median 3-D error <= 0.75 x the measurements'
//   own (1.54 sigma), and the worst <= the measurements' own worst over the same frames.
// The filter before issue 33 (legacyFilterOptions: one straight model, the gate alone) fails the
// turns about an axis off the origin: the origin runs on a circle, which the straight model
// catches only at each 4-sigma gate trip. Figures (this test prints them; sigma 0.3 mm / 0.05 deg,
// the sudden turn 10 cm off): lag before 0.013 deg / 0.53 mm (1.78 sigma), max 0.12 deg / 1.50 mm;
// after 0.016 deg / 0.10 mm (0.34 sigma), max 0.21 deg / 1.12 mm. The price: for ~15 frames after
// a sudden start the estimate is less smoothed (median rotation error over the turn 0.92 sigma,
// before 0.83; one tag 0.76, before 0.55). Run:
// build/tests/tracking/tracking_tests --gtest_filter='TrackingFilter.Turn*'
TEST(TrackingFilter, TurnOfTenDegreesPerFrameFollowedWithinThePerFrameSigma) {
  const std::vector<test::PropMotion> motions = {test::turnMotion(10, 0.0, 0), test::turnMotion(10, 0.1, 0),
                                                 test::turnMotion(10, 0.0, 4), test::turnMotion(10, 0.1, 4),
                                                 test::glideMotion()};
  constexpr int kRuns = 50;
  constexpr unsigned kSeed = 33;
  for (const SigmaLevel& level : kSigmaLevels) {
    for (const test::PropMotion& m : motions) {
      const test::FollowFigures before =
          test::followMotion(m, test::legacyFilterOptions(), level.rotation_rad, level.position_m, kRuns, kSeed);
      const test::FollowFigures after = test::followMotion(m, FilterOptions{}, level.rotation_rad, level.position_m, kRuns, kSeed);
      std::printf("follow: %s; sigma %.2f deg / %.2f mm (%s), %d runs at %.0f fps; measured: median %.2f / %.2f sigma, "
                  "max %.2f / %.2f sigma\n",
                  m.name.c_str(), level.rotation_rad * 180 / M_PI, 1e3 * level.position_m, level.name, kRuns,
                  test::kMotionFps, after.measured_median_rotation, after.measured_median_position,
                  after.measured_max_rotation, after.measured_max_position);
      printFollow("before", before, level);
      printFollow("after", after, level);
      SCOPED_TRACE(m.name + ", " + level.name);
      EXPECT_LE(after.lag_rotation, 1.0);
      EXPECT_LE(after.lag_position, 1.0);
      EXPECT_LE(after.median_rotation, 0.75 * after.measured_median_rotation);
      EXPECT_LE(after.median_position, 0.75 * after.measured_median_position);
      EXPECT_LE(after.max_rotation, after.measured_max_rotation);
      EXPECT_LE(after.max_position, after.measured_max_position);
      // The problem, reproduced: before, the origin off the axis trailed by more than sigma.
      if (m.name.find("10 cm off") != std::string::npos) {
        EXPECT_GT(before.lag_position, 1.0);
      }
    }
  }
}

// Issue 33 item 4, the other half: a still prop stays as steady as before. Generated still poses,
// 20 runs scored as the rendered test above (spread over 100 frames after 10 of warm-up), the same
// seeds through the filter before issue 33 and now: now <= before x 1.05. Figures (printed):
// crate (0.3 mm / 0.05 deg) before 0.2955 mm 0.04621 deg, after 0.2956 mm 0.04621 deg; one tag
// (1 mm / 0.5 deg) before 0.7554 mm 0.2932 deg, after 0.7564 mm 0.2971 deg (+1.3 %).
TEST(TrackingFilter, StillPropJitterNoWorseThanBefore) {
  constexpr int kRuns = 20;
  constexpr unsigned kSeed = 330;
  for (const SigmaLevel& level : kSigmaLevels) {
    const test::Spread before = test::stillJitter(test::legacyFilterOptions(), level.rotation_rad, level.position_m, kRuns, kSeed);
    const test::Spread after = test::stillJitter(FilterOptions{}, level.rotation_rad, level.position_m, kRuns, kSeed);
    std::printf("jitter of a still prop, sigma %.2f deg / %.2f mm (%s): before %.4f mm %.5f deg, after %.4f mm %.5f deg "
                "(raw: %.4f mm %.5f deg)\n",
                level.rotation_rad * 180 / M_PI, 1e3 * level.position_m, level.name, 1e3 * before.position_m,
                before.rotation_rad * 180 / M_PI, 1e3 * after.position_m, after.rotation_rad * 180 / M_PI,
                1e3 * std::sqrt(3.0) * level.position_m, std::sqrt(3.0) * level.rotation_rad * 180 / M_PI);
    SCOPED_TRACE(level.name);
    EXPECT_LE(after.position_m, 1.05 * before.position_m);
    EXPECT_LE(after.rotation_rad, 1.05 * before.rotation_rad);
  }
}

TEST(TrackingFilter, OptionsAreValidated) {
  FilterOptions o;
  o.accel_sigma_mps2 = 0;
  EXPECT_THROW(PoseFilter{o}, Error);
  o = {};
  o.gate_sigma = -1;
  EXPECT_THROW(PoseFilter{o}, Error);
  o = {};
  o.manoeuvre_hold_s = -0.1;
  try {
    PoseFilter{o};
    ADD_FAILURE() << "no error for manoeuvre_hold_s < 0";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "manoeuvre_hold_s");
  }
  o = {};
  o.model_dwell_s = 0;
  EXPECT_THROW(PoseFilter{o}, Error);
  o = {};
  o.manoeuvre_hold_s = 0;  // allowed: the gated frame only
  o.screw_model = false;
  EXPECT_NO_THROW(PoseFilter{o});
}

}  // namespace
}  // namespace previz::tracking
