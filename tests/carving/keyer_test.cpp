// The keyer against the synthetic studio's exact truth, at the real witness size (1280 x 720, the
// take's default 4 samples per pixel): silhouettes vs the true labels of every witness camera on
// three frames across the choreography, with and without a clean plate, noise-free and with
// sensor noise; the soft alpha vs the exact coverage of each pixel's samples; the greenish-grey
// costume kept; the floor shadows dropped; spill removed from the main plate's edges; and the
// cleaning, the options and the errors on small images made by hand.
#include "carving/keyer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/scene.h"
#include "datasets/studio.h"

namespace previz::carving {
namespace {

using synth::ObjectClass;

// Frames across the choreography (10 s take): walking behind the pillar's place, both arms up,
// turning on the spot. Keyed in this order with one Keyer per camera, as a take is.
const double kTimes[] = {2.5, 5.5, 6.2};

double srgbToLinear(int code) {
  static const std::vector<double> table = [] {
    std::vector<double> t(256);
    for (int i = 0; i < 256; ++i) t[static_cast<size_t>(i)] = synth::srgbDecode(i / 255.0);
    return t;
  }();
  return table[static_cast<size_t>(code)];
}

// What the keyer must find: actor and prop (the crate is foreground to a keyer; truth/masks
// holds the actor only, so the labels are the reference).
cv::Mat foregroundTruth(const cv::Mat& labels) {
  return (labels == static_cast<int>(ObjectClass::kActor)) |
         (labels == static_cast<int>(ObjectClass::kProp));
}

struct Studio {
  explicit Studio(synth::Backdrop backdrop = synth::Backdrop::kGreen) : config(configWith(backdrop)) {}
  static synth::StudioConfig configWith(synth::Backdrop backdrop) {
    synth::StudioConfig c;
    c.backdrop = backdrop;
    return c;
  }
  synth::StudioConfig config;
  synth::Studio studio{config};
  Rig rig = synth::studioRig(synth::StudioRigOptions{}, config.take_duration_s, true);

  // What the take's camera 'index' films at time t (layers: scene.h), as synthesizeTake renders
  // it: 4 samples per pixel, no blur, unit gain, sensor noise noise_sigma (grey levels).
  // 'shift_px': the pixel-centre ray of each pixel moved by this (the truth labels at a sample).
  synth::RenderedView render(int index, double time_s, unsigned layers, bool truth = true,
                             double noise_sigma = 0.0,
                             const Eigen::Vector2d& shift_px = Eigen::Vector2d::Zero(), double gain = 1.0) const {
    const RigCamera& c = rig.cameras[static_cast<size_t>(index)];
    const Pose T_world_cam = c.role == "main"
                                 ? synth::mainCameraPose(time_s, config.take_duration_s, true)
                                 : c.T_world_cam;
    const synth::Scene scene = studio.sceneAt(time_s, layers);
    synth::RenderOptions options;
    options.camera_index = index;
    options.truth = truth;
    options.noise_sigma = noise_sigma;
    options.gain = gain;
    // Pixels are K (distorted point) + (cx, cy): a principal point moved by -d puts pixel
    // (u, v)'s centre ray where the original camera's ray through (u, v) + d is.
    Camera camera = c.camera;
    camera.cx -= shift_px.x();
    camera.cy -= shift_px.y();
    return synth::renderView(camera, T_world_cam, scene, options);
  }
  // The exact share of each pixel's samples (the renderer's pattern, 4 per pixel as the take's)
  // that hit the actor or the prop: what a perfect soft key would give.
  cv::Mat coverage(int index, double time_s) const {
    const std::vector<Eigen::Vector2d> pattern = synth::samplePattern(4);
    cv::Mat sum(rig.cameras[static_cast<size_t>(index)].camera.height,
                rig.cameras[static_cast<size_t>(index)].camera.width, CV_32FC1, cv::Scalar(0));
    for (const Eigen::Vector2d& d : pattern) {
      const synth::RenderedView v = render(index, time_s, synth::kLayersPlate, true, 0.0, d);
      cv::Mat hit;
      foregroundTruth(v.labels).convertTo(hit, CV_32FC1, 1.0 / (255.0 * pattern.size()));
      sum += hit;
    }
    return sum;
  }
  int mainIndex() const {
    for (size_t i = 0; i < rig.cameras.size(); ++i) {
      if (rig.cameras[i].role == "main") return static_cast<int>(i);
    }
    return -1;
  }
};

double iou(const cv::Mat& a, const cv::Mat& b) {
  const double inter = cv::countNonZero(a & b), uni = cv::countNonZero(a | b);
  return uni > 0 ? inter / uni : 1.0;
}

// The greenish-grey costume: actor pixels whose own colour is green-dominant in linear light
// (skin, shirt, trousers, shoes and hair are not), away from the silhouette's edge (eroded
// mask), where the pixel is the shaded costume itself.
cv::Mat costumePixels(const cv::Mat& bgr, const cv::Mat& labels) {
  cv::Mat actor = labels == static_cast<int>(ObjectClass::kActor), inner;
  cv::erode(actor, inner, cv::Mat(), cv::Point(-1, -1), 2);
  cv::Mat costume = cv::Mat::zeros(bgr.size(), CV_8UC1);
  for (int y = 0; y < bgr.rows; ++y) {
    for (int x = 0; x < bgr.cols; ++x) {
      const cv::Vec3b p = bgr.at<cv::Vec3b>(y, x);
      if (inner.at<std::uint8_t>(y, x) &&
          srgbToLinear(p[1]) > std::max(srgbToLinear(p[0]), srgbToLinear(p[2]))) {
        costume.at<std::uint8_t>(y, x) = 255;
      }
    }
  }
  return costume;
}

// Floor shadows: stage pixels at least 15 % darker in green than the clean plate, more than
// 2 px from the actor and prop (so the silhouette's own anti-aliased edge does not count).
cv::Mat shadowPixels(const cv::Mat& bgr, const cv::Mat& clean, const cv::Mat& labels) {
  cv::Mat near_fg;
  cv::dilate(foregroundTruth(labels), near_fg, cv::Mat(), cv::Point(-1, -1), 2);
  cv::Mat shadow = cv::Mat::zeros(bgr.size(), CV_8UC1);
  for (int y = 0; y < bgr.rows; ++y) {
    for (int x = 0; x < bgr.cols; ++x) {
      if (labels.at<std::uint8_t>(y, x) != static_cast<int>(ObjectClass::kStage) ||
          near_fg.at<std::uint8_t>(y, x)) {
        continue;
      }
      if (srgbToLinear(bgr.at<cv::Vec3b>(y, x)[1]) < 0.85 * srgbToLinear(clean.at<cv::Vec3b>(y, x)[1])) {
        shadow.at<std::uint8_t>(y, x) = 255;
      }
    }
  }
  return shadow;
}

// One test renders every witness on the three frames (plus one clean plate per camera), noise-free
// and with the sensor noise of the default take (2 grey levels, the clean plate too: the same
// camera shot it), and checks all the silhouette properties on them: rendering dominates the
// cost, so it is done once. The costume and shadow pixels are found on the noise-free render.
TEST(KeyerStudio, WitnessSilhouettesMatchTruthWithAndWithoutCleanPlate) {
  const Studio s;
  const double kNoise[2] = {0.0, 2.0};
  std::vector<double> ious[2][2];  // [noise][without / with plate]
  long long costume_total = 0, costume_kept[2][2] = {};
  long long shadow_total = 0, shadow_in[2][2] = {};
  std::printf("camera     t     IoU(frame) IoU(plate) noise 0 | noise 2  costume px  shadow px in sil (frame/plate)\n");
  for (int cam = 0; cam < static_cast<int>(s.rig.cameras.size()); ++cam) {
    if (s.rig.cameras[static_cast<size_t>(cam)].role != "witness") continue;
    const std::string name = s.rig.cameras[static_cast<size_t>(cam)].camera.name;
    const cv::Mat clean = s.render(cam, kTimes[0], synth::kLayerStage, false).bgr;
    Keyer from_frame[2], from_plate[2];
    from_plate[0].setCleanPlate(clean, name + " clean plate");
    from_plate[1].setCleanPlate(s.render(cam, kTimes[0], synth::kLayerStage, false, kNoise[1]).bgr,
                                name + " clean plate, noise 2");
    for (double t : kTimes) {
      const synth::RenderedView view = s.render(cam, t, synth::kLayersPlate);
      const cv::Mat noisy = s.render(cam, t, synth::kLayersPlate, false, kNoise[1]).bgr;
      const cv::Mat truth = foregroundTruth(view.labels);
      const cv::Mat costume = costumePixels(view.bgr, view.labels);
      const cv::Mat shadow = shadowPixels(view.bgr, clean, view.labels);
      costume_total += cv::countNonZero(costume);
      shadow_total += cv::countNonZero(shadow);
      int costume_in = 0, shadows_in[2] = {0, 0};
      for (int n = 0; n < 2; ++n) {
        const cv::Mat& bgr = n == 0 ? view.bgr : noisy;
        const std::string source = name + " t=" + std::to_string(t) + " noise " + std::to_string(kNoise[n]);
        const KeyResult keys[2] = {from_frame[n].key(bgr, source), from_plate[n].key(bgr, source)};
        for (int mode = 0; mode < 2; ++mode) {
          ASSERT_EQ(keys[mode].silhouette.type(), CV_8UC1);
          ASSERT_EQ(keys[mode].alpha.type(), CV_32FC1);
          const double v = iou(keys[mode].silhouette, truth);
          ious[n][mode].push_back(v);
          EXPECT_GE(v, 0.99) << source << (mode ? " with" : " without") << " clean plate";
          const int kept = cv::countNonZero(costume & keys[mode].silhouette);
          const int in = cv::countNonZero(shadow & keys[mode].silhouette);
          costume_kept[n][mode] += kept;
          shadow_in[n][mode] += in;
          if (n == 0 && mode == 0) costume_in = kept;
          if (n == 0) shadows_in[mode] = in;
        }
      }
      std::printf("%-10s %.1f  %.4f     %.4f           | %.4f %.4f  %5d/%-5d  %d/%d of %d\n", name.c_str(), t,
                  ious[0][0].back(), ious[0][1].back(), ious[1][0].back(), ious[1][1].back(), costume_in,
                  cv::countNonZero(costume), shadows_in[0], shadows_in[1], cv::countNonZero(shadow));
    }
  }
  ASSERT_EQ(ious[0][0].size(), 24u);
  ASSERT_GT(costume_total, 10000);
  ASSERT_GT(shadow_total, 20000);
  for (int n = 0; n < 2; ++n)
    for (int mode = 0; mode < 2; ++mode) {
      std::vector<double> v = ious[n][mode];
      std::sort(v.begin(), v.end());
      std::printf("IoU noise %.0f, %s clean plate: min %.4f median %.4f\n", kNoise[n], mode ? "with" : "without",
                  v.front(), v[v.size() / 2]);
      // The costume (greenish grey, 25 % of the screen's chroma) is foreground: every pixel kept.
      EXPECT_GE(static_cast<double>(costume_kept[n][mode]) / costume_total, 0.999);
      // Shadows on the floor (down to ~45 % of the lit screen) are screen.
      EXPECT_LE(static_cast<double>(shadow_in[n][mode]) / shadow_total, 0.001);
      std::printf("  costume recall %.5f, floor-shadow pixels inside the silhouette %.5f\n",
                  static_cast<double>(costume_kept[n][mode]) / costume_total,
                  static_cast<double>(shadow_in[n][mode]) / shadow_total);
    }
}

// The blue stage (same actor, same lights): every witness on the three frames with sensor noise
// of 2 grey levels, keyed with the backdrop left to the keyer (auto), with and without a clean
// plate. The keyer finds the blue screen on its own, the silhouettes meet the green keyer's
// bound, and the floor shadows stay out.
TEST(KeyerStudio, BlueScreenWitnessesMatchTruth) {
  const Studio s(synth::Backdrop::kBlue);
  std::vector<double> ious[2];
  long long shadow_total = 0, shadow_in[2] = {};
  for (int cam = 0; cam < static_cast<int>(s.rig.cameras.size()); ++cam) {
    if (s.rig.cameras[static_cast<size_t>(cam)].role != "witness") continue;
    const std::string name = s.rig.cameras[static_cast<size_t>(cam)].camera.name;
    const cv::Mat clean = s.render(cam, kTimes[0], synth::kLayerStage, false).bgr;
    Keyer from_frame, from_plate;
    from_plate.setCleanPlate(s.render(cam, kTimes[0], synth::kLayerStage, false, 2.0).bgr, name + " clean plate");
    EXPECT_EQ(from_plate.screen().backdrop, Backdrop::kBlue) << name;
    for (double t : kTimes) {
      const synth::RenderedView view = s.render(cam, t, synth::kLayersPlate);
      const cv::Mat noisy = s.render(cam, t, synth::kLayersPlate, false, 2.0).bgr;
      const cv::Mat truth = foregroundTruth(view.labels);
      const cv::Mat shadow = shadowPixels(view.bgr, clean, view.labels);
      shadow_total += cv::countNonZero(shadow);
      const std::string source = name + " t=" + std::to_string(t);
      const KeyResult keys[2] = {from_frame.key(noisy, source), from_plate.key(noisy, source)};
      EXPECT_EQ(from_frame.screen().backdrop, Backdrop::kBlue) << source;
      for (int mode = 0; mode < 2; ++mode) {
        ious[mode].push_back(iou(keys[mode].silhouette, truth));
        EXPECT_GE(ious[mode].back(), 0.99) << source << (mode ? " with" : " without") << " clean plate";
        shadow_in[mode] += cv::countNonZero(shadow & keys[mode].silhouette);
      }
      std::printf("%-10s %.1f blue screen IoU %.4f (frame) %.4f (plate)\n", name.c_str(), t, ious[0].back(),
                  ious[1].back());
    }
  }
  ASSERT_EQ(ious[0].size(), 24u);
  ASSERT_GT(shadow_total, 20000);
  for (int mode = 0; mode < 2; ++mode) {
    std::sort(ious[mode].begin(), ious[mode].end());
    std::printf("blue screen, noise 2, %s clean plate: IoU min %.4f median %.4f; floor-shadow px in silhouette %.5f\n",
                mode ? "with" : "without", ious[mode].front(), ious[mode][12],
                static_cast<double>(shadow_in[mode]) / shadow_total);
    EXPECT_LE(static_cast<double>(shadow_in[mode]) / shadow_total, 0.001);
  }
}

// No screen: the set (painted panels, an oak floor, the same lights and shadows), each witness
// with its clean plate, sensor noise 2 on plate and frames, and the frames' exposure drifting
// +3 %, -3 %, 0 % from the plate's. The backdrop is left to the keyer (auto: no screen in the
// plate, so difference keying). Beside it, the green keyer with its plate on the green studio,
// same frames, same noise and drift. Measured: difference IoU median 0.992, min 0.982, no
// floor-shadow pixel keyed; green 0.9953 / 0.9918. Shadows judged per pixel alone (before the
// 5 x 5 hue test, keyer.h shadow_hue_levels): min 0.955, 2 of 24 below 0.97, the lost parts dark
// brown hair over the dark grey wall and a grey crate top over a warm panel, each the plate
// darkened within one pixel's noise but off its hue by 5-9 levels at every pixel. What is still
// lost is where the actor is the background within noise (hair lit by the fill alone in front of
// the black drapes, both ~0.03 linear).
TEST(KeyerStudio, NoScreenSetKeyedByDifferenceAgainstTheCleanPlate) {
  const Studio set(synth::Backdrop::kSet), green(synth::Backdrop::kGreen);
  const double kGain[3] = {1.03, 0.97, 1.0};
  std::vector<double> ious[2];  // [set, green]
  long long keyed[2] = {}, shadow_in[2] = {}, shadow_total = 0;
  for (int cam = 0; cam < static_cast<int>(set.rig.cameras.size()); ++cam) {
    if (set.rig.cameras[static_cast<size_t>(cam)].role != "witness") continue;
    const std::string name = set.rig.cameras[static_cast<size_t>(cam)].camera.name;
    Keyer keyers[2];
    const Studio* studios[2] = {&set, &green};
    cv::Mat clean[2];
    for (int k = 0; k < 2; ++k) {
      clean[k] = studios[k]->render(cam, kTimes[0], synth::kLayerStage, false).bgr;
      keyers[k].setCleanPlate(studios[k]->render(cam, kTimes[0], synth::kLayerStage, false, 2.0).bgr,
                              name + " clean plate");
    }
    EXPECT_EQ(keyers[0].screen().backdrop, Backdrop::kNone) << name;
    EXPECT_EQ(keyers[1].screen().backdrop, Backdrop::kGreen) << name;
    for (int i = 0; i < 3; ++i) {
      const double t = kTimes[i];
      const std::string source = name + " t=" + std::to_string(t);
      double v[2];
      for (int k = 0; k < 2; ++k) {
        const synth::RenderedView view = studios[k]->render(cam, t, synth::kLayersPlate, true, 0.0, Eigen::Vector2d::Zero(),
                                                                     kGain[i]);
        const cv::Mat frame =
            studios[k]->render(cam, t, synth::kLayersPlate, false, 2.0, Eigen::Vector2d::Zero(), kGain[i]).bgr;
        const cv::Mat truth = foregroundTruth(view.labels);
        // Floor shadows: 15 % darker than the plate, more than the drift.
        const cv::Mat shadow = shadowPixels(view.bgr, clean[k], view.labels);
        if (k == 0) shadow_total += cv::countNonZero(shadow);
        const KeyResult key = keyers[k].key(frame, source);
        v[k] = iou(key.silhouette, truth);
        ious[k].push_back(v[k]);
        keyed[k] += cv::countNonZero(key.silhouette);
        shadow_in[k] += cv::countNonZero(shadow & key.silhouette);
        if (k == 0) {
          EXPECT_GE(v[k], 0.97) << source;
          // The exposure found is the drift (the plate's gain is 1).
          EXPECT_NEAR(keyers[k].screen().exposure_gain, kGain[i], 0.01) << source;
        }
      }
      std::printf("%-10s %.1f gain %.2f: set (difference) IoU %.4f, exposure %.4f | green (chroma) IoU %.4f\n",
                  name.c_str(), t, kGain[i], v[0], keyers[0].screen().exposure_gain, v[1]);
    }
  }
  ASSERT_EQ(ious[0].size(), 24u);
  ASSERT_GT(shadow_total, 20000);
  for (int k = 0; k < 2; ++k) {
    std::sort(ious[k].begin(), ious[k].end());
    std::printf("%s: IoU min %.4f median %.4f; floor-shadow px inside the silhouette %lld = %.4f %% of keyed px\n",
                k == 0 ? "no screen, difference keying" : "green screen, chroma keying", ious[k].front(),
                ious[k][12], shadow_in[k], 100.0 * static_cast<double>(shadow_in[k]) / keyed[k]);
  }
  EXPECT_GE(ious[0][12], 0.97);  // the median
  EXPECT_LE(static_cast<double>(shadow_in[0]) / keyed[0], 0.005);
}

// A camera's footage has sensor noise: the same frame (t = 5.5 s, every witness, no clean plate,
// as the default take is keyed) rendered with Gaussian noise of 2 grey levels keys nearly as
// well as the noise-free render, and the noise adds no silhouette and almost no alpha away from
// the actor (more than 3 px from the true foreground). Measured: IoU 0 to 0.0012 below the
// noise-free key's; alpha > 0 added on 9.9e-7 of the pixels away from the actor (1.7e-5 before
// pixels near the drapes' colour were decided by their 3 x 3 mean, 5.2e-5 when lone unknown
// pixels are not taken for noise either).
TEST(KeyerStudio, SensorNoiseCostsTheSilhouettesLittle) {
  const Studio s;
  const double t = 5.5;
  long long stray_alpha = 0, far_px = 0, lone = 0;
  for (int cam = 0; cam < static_cast<int>(s.rig.cameras.size()); ++cam) {
    if (s.rig.cameras[static_cast<size_t>(cam)].role != "witness") continue;
    const std::string name = s.rig.cameras[static_cast<size_t>(cam)].camera.name;
    const synth::RenderedView clean = s.render(cam, t, synth::kLayersPlate);
    const synth::RenderedView noisy = s.render(cam, t, synth::kLayersPlate, false, 2.0);
    const cv::Mat truth = foregroundTruth(clean.labels);
    Keyer from_clean, from_noisy;
    const KeyResult a = from_clean.key(clean.bgr, name + " noise-free");
    const KeyResult b = from_noisy.key(noisy.bgr, name + " noise 2");
    const double iou_clean = iou(a.silhouette, truth), iou_noisy = iou(b.silhouette, truth);
    std::printf("%-10s IoU noise-free %.4f, noise 2 %.4f; lone unknown px %d\n", name.c_str(), iou_clean,
                iou_noisy, b.stats.lone_unknown_px);
    // (A fresh Keyer: no memory of the surroundings seen through the gap between the raised arm
    // and the head, so witness03 is at 0.986 here, 0.996 in a take; the main test keys in order.)
    ASSERT_GT(iou_clean, 0.98) << name;
    EXPECT_GE(iou_noisy, iou_clean - 0.003) << name;
    cv::Mat near;
    cv::dilate(truth, near, cv::Mat(), cv::Point(-1, -1), 3);
    const cv::Mat far = ~near;
    // What the noise adds away from the actor (both keys may hold some of that gap).
    EXPECT_EQ(cv::countNonZero(b.silhouette & ~a.silhouette & far), 0) << name;
    stray_alpha += cv::countNonZero((b.alpha > 0) & (a.alpha == 0) & far);
    far_px += cv::countNonZero(far);
    lone += b.stats.lone_unknown_px;
  }
  ASSERT_GT(far_px, 5000000);
  std::printf("alpha > 0 away from the actor: %lld of %lld px (%.1e); lone unknown px %lld\n", stray_alpha,
              far_px, static_cast<double>(stray_alpha) / far_px, lone);
  EXPECT_LE(static_cast<double>(stray_alpha) / far_px, 5e-5);
  // The noise does reach the first pass's unknown class (929 measured; most noisy pixels near the
  // drapes' colour are decided by their 3 x 3 mean before that).
  EXPECT_GT(lone, 500);
}

// The soft alpha against the exact coverage of each pixel by the actor and prop (the share of
// its 4 samples that hit them), on every witness at t = 5.5 s, noise-free and with sensor noise of
// 2 grey levels, no clean plate: the RMS and the mean (bias) of alpha - coverage over the mixed
// pixels (0 < coverage < 1). Measured over 9735 mixed px: noise-free RMS 0.087, mean -0.010; noise
// 2: RMS 0.104, mean -0.007. With F the purest aligned neighbour alone (before F was a mean):
// 0.091 / -0.018 and 0.109 / -0.023, the edge pulled in by about a fiftieth of a pixel.
TEST(KeyerStudio, SoftAlphaMatchesTheExactCoverage) {
  const Studio s;
  const double t = 5.5;
  const double noise[2] = {0.0, 2.0};
  double sum2[2] = {0, 0}, sum[2] = {0, 0};
  long long mixed_px = 0;
  for (int cam = 0; cam < static_cast<int>(s.rig.cameras.size()); ++cam) {
    if (s.rig.cameras[static_cast<size_t>(cam)].role != "witness") continue;
    const std::string name = s.rig.cameras[static_cast<size_t>(cam)].camera.name;
    const cv::Mat coverage = s.coverage(cam, t);
    const cv::Mat mixed = (coverage > 0.0f) & (coverage < 1.0f);
    mixed_px += cv::countNonZero(mixed);
    for (int i = 0; i < 2; ++i) {
      Keyer keyer;
      const KeyResult key = keyer.key(s.render(cam, t, synth::kLayersPlate, false, noise[i]).bgr,
                                      name + " noise " + std::to_string(noise[i]));
      for (int y = 0; y < mixed.rows; ++y)
        for (int x = 0; x < mixed.cols; ++x) {
          if (!mixed.at<std::uint8_t>(y, x)) continue;
          const double e = key.alpha.at<float>(y, x) - coverage.at<float>(y, x);
          sum[i] += e;
          sum2[i] += e * e;
        }
    }
  }
  ASSERT_GT(mixed_px, 5000);
  for (int i = 0; i < 2; ++i) {
    const double rms = std::sqrt(sum2[i] / mixed_px), bias = sum[i] / mixed_px;
    std::printf("noise %.0f: alpha - coverage over %lld mixed px: RMS %.4f, mean %+.4f\n", noise[i],
                mixed_px, rms, bias);
    // A quarter-sample step of coverage is 0.25: well within it, and no systematic pull.
    EXPECT_LE(rms, i == 0 ? 0.09 : 0.11) << "noise " << noise[i];
    EXPECT_LE(std::abs(bias), 0.012) << "noise " << noise[i];
  }
  EXPECT_LE(std::sqrt(sum2[1] / mixed_px), std::sqrt(sum2[0] / mixed_px) + 0.025);  // noise costs little
}

// Main plate: on the silhouette's edge (0.1 < alpha < 0.9) the raw pixel is a mix with the screen
// (its channel above the other two); despilled, it is the foreground's own colour. The truth is
// the same frame rendered without the stage: C = alpha F + (1 - alpha) E with E the dark
// environment. 'screen': the screen's channel (B, G, R order); 'min_edge_px': edge pixels the
// frame must offer; 'own_kept': the share of the screen-coloured costume's edge pixels that must
// keep their own colour above the others.
void checkDespill(synth::Backdrop backdrop, int screen, long long min_edge_px, double own_kept) {
  const Studio s(backdrop);
  const int main = s.mainIndex();
  ASSERT_GE(main, 0);
  const double t = 8.5;  // walking along the front: the main camera sees the costume from the side
  const synth::RenderedView plate = s.render(main, t, synth::kLayersPlate);
  const cv::Mat alone = s.render(main, t, synth::kLayerActor | synth::kLayerProp, false).bgr;
  const double environment = synth::Scene{}.environment_rgb.x();  // grey, all channels alike
  Keyer keyer;
  const KeyResult key = keyer.key(plate.bgr, "main");
  EXPECT_GE(iou(key.silhouette, foregroundTruth(plate.labels)), 0.98);
  const cv::Mat out = despill(plate.bgr, key, keyer.screen());
  ASSERT_EQ(out.type(), CV_8UC3);
  ASSERT_EQ(out.size(), plate.bgr.size());

  long long edge = 0, green_before = 0, green_after = 0, greenish = 0, greenish_kept = 0;
  double greenish_err_before = 0, greenish_err_after = 0;
  long long opaque = 0, opaque_changed = 0;
  double err_before = 0, err_after = 0;
  for (int y = 0; y < out.rows; ++y) {
    for (int x = 0; x < out.cols; ++x) {
      const float a = key.alpha.at<float>(y, x);
      const cv::Vec3b c = plate.bgr.at<cv::Vec3b>(y, x), o = out.at<cv::Vec3b>(y, x);
      if (a >= 1.0f) {
        ++opaque;
        opaque_changed += c != o;
        continue;
      }
      if (a < 0.1f || a > 0.9f) continue;
      double f[3], raw[3], after[3];
      for (int ch = 0; ch < 3; ++ch) {
        f[ch] = (srgbToLinear(alone.at<cv::Vec3b>(y, x)[ch]) - (1.0 - a) * environment) / a;
        raw[ch] = srgbToLinear(c[ch]);
        after[ch] = srgbToLinear(o[ch]);
      }
      auto excess = [&](const double* v) { return v[screen] - std::max(v[(screen + 1) % 3], v[(screen + 2) % 3]); };
      if (excess(f) > 0) {
        // The greenish costume's own edge: its green is not spill, and stays.
        ++greenish;
        greenish_kept += excess(after) > 0;
        for (int ch = 0; ch < 3; ++ch) {
          greenish_err_before += std::abs(raw[ch] - f[ch]) / 3;
          greenish_err_after += std::abs(after[ch] - f[ch]) / 3;
        }
        continue;
      }
      ++edge;
      green_before += excess(raw) > 0.01;
      green_after += excess(after) > 0.01;
      for (int ch = 0; ch < 3; ++ch) {
        err_before += std::abs(raw[ch] - f[ch]) / 3;
        err_after += std::abs(after[ch] - f[ch]) / 3;
      }
    }
  }
  std::printf("%s screen, main t=%.1f: %lld edge px; screen channel above the others + 0.01: %lld before, %lld after; "
              "mean |F - F_true| (linear) %.4f before, %.4f after; costume edge px: %lld keep "
              "green above red and blue of %lld, mean |F - F_true| %.4f before, %.4f after; "
              "opaque px changed %lld/%lld\n",
              synth::toString(backdrop), t, edge, green_before, green_after, err_before / edge, err_after / edge,
              greenish_kept, greenish, greenish_err_before / std::max(1LL, greenish),
              greenish_err_after / std::max(1LL, greenish), opaque_changed, opaque);
  ASSERT_GT(edge, min_edge_px);
  EXPECT_GT(green_before, edge / 2);            // the raw edges carry the screen
  EXPECT_LE(green_after, edge / 100);           // despilled: green no longer above red and blue
  EXPECT_LT(err_after / edge, 0.02);            // and the colour is the foreground's
  EXPECT_LT(err_after, 0.25 * err_before);
  EXPECT_EQ(opaque_changed, 0);                 // what is opaque is left as it is
  ASSERT_GT(opaque, 10000);
  ASSERT_GT(greenish, 20);
  EXPECT_GE(greenish_kept, own_kept * greenish);  // the costume's own colour is not spill
  EXPECT_LT(greenish_err_after, 0.5 * greenish_err_before);
}

TEST(KeyerStudio, DespillRemovesScreenFromEdgesAndKeepsOpaqueColours) {
  checkDespill(synth::Backdrop::kGreen, 1, 1000, 0.75);
}

// The same on the blue stage (the actor unchanged; the dark screen leaves fewer mixed edge
// pixels: 936): blue spill removed as green is. The navy trousers are blue-dominant at half the
// screen's chroma (the greenish costume on green: a quarter), so on their edges their own blue
// and the screen's cannot be told apart: 169 of 652 keep blue above red and green, yet their
// colour error still falls from 0.072 to 0.020 (the bound below: halved). Measured: edge error
// 0.078 -> 0.006, blue above the others on 809 -> 4 of 936.
TEST(KeyerStudio, DespillOfABlueScreen) { checkDespill(synth::Backdrop::kBlue, 0, 800, 0.2); }

// A hand-made frame: the screen colour with a shadowed band, a thin limb (2 px), a speck, a
// hole, a dark neutral tag-like patch inside a white box and a greenish-grey patch.
TEST(Keyer, CleansSpecksAndHolesButKeepsThinLimbs) {
  const cv::Vec3b screen(99, 183, 81), shadowed(66, 124, 53), costume(129, 143, 126);
  cv::Mat img(240, 320, CV_8UC3, screen);
  img(cv::Rect(0, 180, 320, 30)).setTo(shadowed);              // floor shadow
  img(cv::Rect(40, 40, 60, 120)).setTo(cv::Vec3b(60, 70, 170));  // torso
  img(cv::Rect(100, 60, 120, 2)).setTo(cv::Vec3b(60, 70, 170));  // thin limb, 2 px
  img(cv::Rect(60, 80, 5, 5)).setTo(screen);                     // hole, 25 px
  img(cv::Rect(260, 30, 4, 4)).setTo(cv::Vec3b(60, 70, 170));    // speck, 16 px
  img(cv::Rect(150, 120, 40, 40)).setTo(cv::Vec3b(200, 200, 200));  // white box
  img(cv::Rect(160, 130, 20, 20)).setTo(cv::Vec3b(10, 10, 10));     // dark patch in it
  img(cv::Rect(230, 120, 30, 40)).setTo(costume);
  Keyer keyer;
  const KeyResult r = keyer.key(img, "hand-made");
  auto at = [&](int x, int y) { return r.silhouette.at<std::uint8_t>(y, x); };
  EXPECT_EQ(at(70, 100), 255);   // torso
  EXPECT_EQ(at(62, 82), 255);    // hole filled
  EXPECT_EQ(at(200, 60), 255);   // limb kept, full width
  EXPECT_EQ(at(200, 61), 255);
  EXPECT_EQ(at(200, 59), 0);
  EXPECT_EQ(at(200, 62), 0);
  EXPECT_EQ(at(261, 31), 0);     // speck removed
  EXPECT_EQ(at(170, 140), 255);  // dark patch inside the box: foreground (no surroundings here)
  EXPECT_EQ(at(245, 140), 255);  // greenish grey
  EXPECT_EQ(at(20, 195), 0);     // shadowed screen
  EXPECT_EQ(at(20, 20), 0);
  EXPECT_EQ(r.stats.specks_removed, 1);
  EXPECT_EQ(r.stats.holes_filled, 1);
  // Nothing but the hand-made objects: area within the rounding of their edges.
  const int expected = 60 * 120 + 120 * 2 + 40 * 40 + 30 * 40;
  EXPECT_NEAR(cv::countNonZero(r.silhouette), expected, 4);
}

// Sensor noise on the screen: pixels that the first pass cannot call screen, alone or in a
// cluster within 3 x 3 among screen pixels, are background (noise, not a part of the actor),
// neither refined nor turned into specks. The same colour on a one-pixel diagonal strand
// (8-connected, longer than a speck) or on a run of 4 pixels is refined as before: the strand is
// kept, the run is a speck.
TEST(Keyer, LoneUnknownPixelsAreScreenNoiseButThinStrandsAreRefined) {
  const cv::Vec3b screen(99, 183, 81), torso(60, 70, 170);
  // 35 % torso, 65 % screen, mixed in linear light: 55 % of the screen's chroma, between the
  // screen's (85 %) and the foreground's (40 %) thresholds, so the first pass leaves it unknown.
  const cv::Vec3b mix(88, 155, 122);
  cv::Mat img(240, 320, CV_8UC3, screen);
  img(cv::Rect(40, 40, 60, 120)).setTo(torso);
  const cv::Point lone[] = {{150, 30}, {200, 100}, {250, 200}, {300, 50}, {120, 220}};
  for (const cv::Point& p : lone) img.at<cv::Vec3b>(p) = mix;
  for (int i = 0; i < 80; ++i) img.at<cv::Vec3b>(110 + i, 150 + i) = mix;  // diagonal strand
  img.at<cv::Vec3b>(180, 160) = img.at<cv::Vec3b>(181, 161) = mix;         // a diagonal pair
  img(cv::Rect(100, 200, 4, 1)).setTo(mix);                                // a run of 4
  Keyer keyer;
  const KeyResult r = keyer.key(img, "hand-made");
  EXPECT_EQ(r.stats.lone_unknown_px, 5 + 2);
  EXPECT_EQ(r.stats.specks_removed, 1);  // the run
  for (const cv::Point& p : {lone[0], lone[1], lone[2], lone[3], lone[4], cv::Point(160, 180)}) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        EXPECT_EQ(r.alpha.at<float>(p.y + dy, p.x + dx), 0.0f) << p << " + (" << dx << ", " << dy << ")";
      }
    }
  }
  for (int i = 0; i < 80; ++i) {
    EXPECT_GE(r.alpha.at<float>(110 + i, 150 + i), 0.3f) << "strand pixel " << i;
    EXPECT_EQ(r.silhouette.at<std::uint8_t>(110 + i, 150 + i), 255) << "strand pixel " << i;
  }
  EXPECT_EQ(r.silhouette.at<std::uint8_t>(100, 70), 255);  // the torso
  EXPECT_EQ(cv::countNonZero(r.silhouette), 60 * 120 + 80);
}

// The surroundings beyond the screen (a dark grey band along the top border, as a witness sees
// the studio over the cyclorama) are background; the actor standing in front of them is not, and
// neither is a dark grey patch of the actor's own away from them.
TEST(Keyer, GarbageMatteDropsSurroundingsConnectedToTheBorderOnly) {
  const cv::Vec3b screen(99, 183, 81), studio(52, 50, 50), skin(120, 150, 200);
  cv::Mat img(240, 320, CV_8UC3, screen);
  img(cv::Rect(0, 0, 320, 50)).setTo(studio);
  img(cv::Rect(100, 30, 30, 150)).setTo(skin);            // stands in front of the studio
  img(cv::Rect(200, 120, 30, 30)).setTo(skin);
  img(cv::Rect(210, 130, 10, 10)).setTo(studio);          // studio-coloured patch on it
  Keyer keyer;
  const KeyResult r = keyer.key(img, "hand-made");
  auto at = [&](int x, int y) { return r.silhouette.at<std::uint8_t>(y, x); };
  EXPECT_EQ(at(20, 20), 0);      // surroundings
  EXPECT_EQ(at(115, 40), 255);   // actor over the surroundings
  EXPECT_EQ(at(115, 100), 255);
  EXPECT_EQ(at(215, 135), 255);  // dark patch enclosed by the actor
  EXPECT_GT(r.stats.garbage_px, 300 * 40);
  EXPECT_NEAR(cv::countNonZero(r.silhouette), 30 * 150 + 30 * 30, 4);
}

TEST(Keyer, SoftAlphaCanBeSkipped) {
  cv::Mat img(60, 80, CV_8UC3, cv::Vec3b(99, 183, 81));
  img(cv::Rect(20, 20, 30, 20)).setTo(cv::Vec3b(60, 70, 170));
  KeyerOptions options;
  options.soft_alpha = false;
  Keyer keyer(options);
  const KeyResult r = keyer.key(img);
  EXPECT_TRUE(r.alpha.empty());
  EXPECT_EQ(cv::countNonZero(r.silhouette), 30 * 20);
  EXPECT_THROW(despill(img, r, keyer.screen()), Error);
}

TEST(Keyer, BadInputNamesTheSource) {
  Keyer keyer;
  try {
    keyer.key(cv::Mat(), "cams/witness03/000012.png");
    FAIL() << "empty image accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, "cams/witness03/000012.png");
    EXPECT_NE(std::string(e.what()).find("empty"), std::string::npos) << e.what();
  }
  try {
    keyer.key(cv::Mat(10, 10, CV_8UC1, cv::Scalar(0)), "cams/main/000001.png");
    FAIL() << "grey image accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, "cams/main/000001.png");
    EXPECT_NE(std::string(e.what()).find("8-bit 3-channel"), std::string::npos) << e.what();
  }
  // No screen in view: nothing to key against.
  EXPECT_THROW(keyer.key(cv::Mat(40, 40, CV_8UC3, cv::Scalar(128, 128, 128)), "grey"), Error);
  // A frame unlike the clean plate's size.
  Keyer with_plate;
  with_plate.setCleanPlate(cv::Mat(40, 40, CV_8UC3, cv::Scalar(99, 183, 81)), "plate");
  try {
    with_plate.key(cv::Mat(20, 40, CV_8UC3, cv::Scalar(99, 183, 81)), "frame 7");
    FAIL() << "size mismatch accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, "frame 7");
  }
}

TEST(Keyer, OptionsNameTheBadField) {
  auto field = [](KeyerOptions o) {
    try {
      o.validate();
    } catch (const Error& e) {
      return e.context().field;
    }
    return std::string();
  };
  EXPECT_EQ(field(KeyerOptions{}), "");
  KeyerOptions o;
  o.silhouette_threshold = 1.5;
  EXPECT_EQ(field(o), "silhouette_threshold");
  o = {};
  o.min_blob_px = -1;
  EXPECT_EQ(field(o), "min_blob_px");
  o = {};
  o.edge_radius_px = 0;
  EXPECT_EQ(field(o), "edge_radius_px");
  o = {};
  o.plate_tolerance = 0;
  EXPECT_EQ(field(o), "plate_tolerance");
  o = {};
  o.threads = -2;
  EXPECT_EQ(field(o), "threads");
  o = {};
  o.min_shadow = 1.0;
  EXPECT_EQ(field(o), "min_shadow");
  o = {};
  o.shadow_hue_levels = -1;
  EXPECT_EQ(field(o), "shadow_hue_levels");
  o = {};
  o.region_margin_px = -1;
  EXPECT_EQ(field(o), "region_margin_px");
  o = {};
  o.region_full_every = -1;
  EXPECT_EQ(field(o), "region_full_every");
  o = {};
  o.min_hole_px = -3;
  EXPECT_THROW(Keyer{o}, Error);
}

// OpenMP changes nothing: rows are independent and every reduction is an integer count.
// Region keying (KeyerOptions::region_margin_px), as the live loop keys: consecutive frames at
// 24 fps with sensor noise, every witness (no clean plate, the garbage memory on) and the moving
// main camera (soft alpha), keyed whole and by region. The region keyer must give the whole
// keyer's silhouette exactly, and its alpha inside the region, while keying only the region
// after the first frame.
TEST(KeyerStudio, RegionKeyingMatchesWholeFramesOnConsecutiveFrames) {
  const Studio s;
  constexpr int kFrames = 4;
  long long region_frames = 0, region_px = 0, frame_px = 0, main_differs = 0;
  const int cameras[] = {0, 3, 5, s.mainIndex()};  // witness01, 04, 06 (the drapes), main
  for (const int cam : cameras) {
    const RigCamera& rc = s.rig.cameras[static_cast<size_t>(cam)];
    KeyerOptions whole_opts;
    whole_opts.threads = 1;
    if (rc.role == "main") whole_opts.remember_garbage_zone = false;
    else whole_opts.soft_alpha = false;
    KeyerOptions region_opts = whole_opts;
    region_opts.region_margin_px = 48;
    Keyer whole(whole_opts), region(region_opts);
    // The region key's result is reused frame after frame, as the live loop does, and holds
    // stale values everywhere before each call: every pixel the keyer leaves unwritten shows.
    KeyResult b;
    for (int f = 0; f < kFrames; ++f) {
      const double t = 5.5 + f / 24.0;
      const std::string source = rc.camera.name + " frame " + std::to_string(f);
      const cv::Mat frame = s.render(cam, t, synth::kLayersPlate, false, 2.0).bgr;
      if (!b.silhouette.empty()) b.silhouette.setTo(255);
      if (!b.alpha.empty()) b.alpha.setTo(1.0f);
      const KeyResult a = whole.key(frame, source);
      region.key(frame, source, b);
      EXPECT_EQ(cv::countNonZero(a.silhouette != b.silhouette), 0) << source;
      if (rc.role == "main") {
        // Soft alpha: the same inside the region; outside it the whole key leaves alpha on a few
        // lone pixels of sensor noise and far-off edges (never silhouette: decided on their 3 x 3
        // mean), which the region key leaves at 0.
        const cv::Mat differs = a.alpha != b.alpha;
        cv::Rect box = cv::boundingRect(b.silhouette);  // within the region (a few px a frame)
        box = cv::Rect(box.x - 40, box.y - 40, box.width + 80, box.height + 80) & cv::Rect(0, 0, frame.cols, frame.rows);
        main_differs += cv::countNonZero(differs);
        if (f > 0) {
          EXPECT_EQ(cv::countNonZero(differs(box)), 0) << source;
        }
        EXPECT_EQ(cv::countNonZero(differs & a.silhouette), 0) << source;
        EXPECT_EQ(cv::countNonZero((b.alpha > 0) & (a.alpha == 0)), 0) << source;
        EXPECT_LE(cv::countNonZero(differs), 50) << source;
      }
      if (f == 0) {
        EXPECT_TRUE(b.stats.whole_frame) << source;
        EXPECT_EQ(b.stats.whole_frame_reason, "no earlier silhouette") << source;
      } else {
        EXPECT_FALSE(b.stats.whole_frame) << source << ": " << b.stats.whole_frame_reason;
        region_frames += !b.stats.whole_frame;
        region_px += b.stats.keyed_px;
        frame_px += frame.total();
        EXPECT_LT(b.stats.keyed_px, static_cast<int>(frame.total()) / 2) << source;
      }
    }
  }
  std::printf("region keying: %lld frames keyed by region, regions %.1f %% of the frames' pixels; main alpha "
              "differs (outside the region, never silhouette) on %lld px\n",
              region_frames, 100.0 * static_cast<double>(region_px) / static_cast<double>(frame_px), main_differs);
  EXPECT_EQ(region_frames, 4 * (kFrames - 1));
}

// Region keying sends a frame to a whole key when something new shows outside the region (an
// actor walking in: found on the probed rows), when the silhouette runs into the region's edge
// (it moved more than the margin), periodically, and after resetRegion(); each time the result
// is the whole keyer's.
TEST(Keyer, RegionKeyingFallsBackToWholeFramesWhenItMustAndSaysWhy) {
  const cv::Vec3b screen(99, 183, 81), red(60, 70, 170);
  // The actor (40 x 160), an arm held out (rows 150-155, between the probed rows 148 and 156),
  // a newcomer at the top right (rows 20-31).
  auto frame = [&](int actor_x, bool arm, bool newcomer) {
    cv::Mat img(360, 480, CV_8UC3, screen);
    img(cv::Rect(actor_x, 100, 40, 160)).setTo(red);
    if (arm) img(cv::Rect(actor_x + 40, 150, 52, 6)).setTo(red);
    if (newcomer) img(cv::Rect(420, 20, 30, 12)).setTo(red);
    return img;
  };
  KeyerOptions o;
  o.region_margin_px = 16;
  o.region_full_every = 6;
  Keyer whole, region(o);
  struct Step {
    int actor_x;
    bool arm, newcomer;
    bool whole_frame;
    std::string reason;
  };
  const Step steps[] = {
      {100, false, false, true, "no earlier silhouette"},
      {104, false, false, false, ""},
      {108, false, false, false, ""},
      {108, true, false, true, "silhouette reached the region's edge"},
      {110, true, true, true, "foreground outside the region"},
      {112, true, true, false, ""},
      {114, true, true, true, "periodic whole frame"},
      {116, true, true, false, ""},
  };
  int i = 0;
  for (const Step& step : steps) {
    const std::string source = "step " + std::to_string(i++);
    const cv::Mat img = frame(step.actor_x, step.arm, step.newcomer);
    const KeyResult a = whole.key(img, source), b = region.key(img, source);
    EXPECT_EQ(b.stats.whole_frame, step.whole_frame) << source << ": " << b.stats.whole_frame_reason;
    if (step.whole_frame) {
      EXPECT_EQ(b.stats.whole_frame_reason, step.reason) << source;
    }
    EXPECT_EQ(cv::countNonZero(a.silhouette != b.silhouette), 0) << source;
    EXPECT_EQ(cv::norm(a.alpha, b.alpha, cv::NORM_INF), 0.0) << source;
    if (step.whole_frame) {
      EXPECT_EQ(b.stats.keyed_px, 480 * 360) << source;
    } else if (step.newcomer) {
      // Two parts, two regions: the last frame's actor with the arm (110..202 x 100..260) and the
      // newcomer (420..450 x 20..32), each grown by the 16 px margin. One box around both would
      // be 372 x 272 px.
      EXPECT_EQ(b.stats.keyed_px, (92 + 32) * (160 + 32) + (30 + 32) * (12 + 32)) << source;
    }
  }
  region.resetRegion();
  const KeyResult b = region.key(frame(116, true, true), "after reset");
  EXPECT_TRUE(b.stats.whole_frame);
  EXPECT_EQ(b.stats.whole_frame_reason, "no earlier silhouette");
}

TEST(Keyer, SameResultForAnyThreadCount) {
  const Studio s;
  const cv::Mat bgr = s.render(4, kTimes[1], synth::kLayersPlate, false).bgr;
  KeyerOptions one;
  one.threads = 1;
  KeyerOptions four;
  four.threads = 4;
  Keyer a(one), b(four);
  const KeyResult ra = a.key(bgr), rb = b.key(bgr);
  EXPECT_EQ(cv::countNonZero(ra.silhouette != rb.silhouette), 0);
  EXPECT_EQ(cv::norm(ra.alpha, rb.alpha, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace previz::carving
