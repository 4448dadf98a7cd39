// Focus measures and soft-view rejection on synthetic sequences whose blur is known: the studio
// renderer applies a Gaussian defocus of a given sigma (pixels, linear light).
#include "calib/focus.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "calib/detect.h"
#include "core/error.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace previz::calib {
namespace {

constexpr double kDeg = M_PI / 180.0;

Camera testCamera() {
  Camera c;
  c.name = "focus";
  c.width = 640;
  c.height = 480;
  c.fx = c.fy = 480.0;
  c.cx = 319.5;
  c.cy = 239.5;
  c.dist.k1 = -0.15;
  c.dist.k2 = 0.03;
  return c;
}

Pose boardPose(const Camera& camera, const BoardSpec& spec, double coverage, double tilt_x_deg,
               double tilt_y_deg, double roll_deg) {
  const Eigen::Vector2d size = spec.size_m();
  const double distance = camera.fx * (size.x() + 2 * spec.margin_m) / (coverage * camera.width);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(roll_deg * kDeg, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(tilt_x_deg * kDeg, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(tilt_y_deg * kDeg, Eigen::Vector3d::UnitY()))
                                .toRotationMatrix();
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() =
      Eigen::Vector3d(0, 0, distance) - R * Eigen::Vector3d(0.5 * size.x(), 0.5 * size.y(), 0);
  return T;
}

cv::Mat render(const Camera& camera, const BoardSpec& spec, const Pose& T_cam_board,
               double blur_sigma_px, double noise_sigma, int frame) {
  static const synth::Studio studio([] {
    synth::StudioConfig config;
    config.with_actor = false;
    config.with_prop = false;
    return config;
  }());
  const Pose T_world_cam = synth::mainCameraPose(0.0, 1.0, false);
  synth::Scene scene = studio.sceneAt(0.0, synth::kLayerStage);
  scene.add(synth::makeBoard(spec, T_world_cam * T_cam_board));
  synth::RenderOptions options;
  options.blur_sigma_px = blur_sigma_px;
  options.noise_sigma = noise_sigma;
  options.frame = frame;
  return synth::renderView(camera, T_world_cam, scene, options).bgr;
}

struct Shot {
  double coverage, tilt_x, tilt_y, roll, blur, noise;
};

// Boards from 35 % to 85 % of the image width (squares of ~17 to ~42 px), tilted up to 40
// degrees; blurred ones (sigma >= 2.5 px) near and far, one of them also noisy; two sharp ones
// with noise sigma 1 (grey levels).
const std::vector<Shot> kSequence = {
    {0.80, 0, 0, 0, 0, 0},       {0.45, 20, -10, 5, 0, 1.0}, {0.70, -15, 25, -8, 2.5, 0},
    {0.35, 30, 10, 12, 0, 0},    {0.60, -25, -20, 3, 0, 0},  {0.40, 10, 35, -5, 3.0, 0},
    {0.85, 5, -5, 90, 0, 0},     {0.55, -35, 15, 8, 0, 1.0}, {0.65, 15, -30, -12, 0, 0},
    {0.50, 25, 25, 180, 4.0, 0}, {0.38, -10, -35, 6, 0, 0},  {0.75, 40, 0, -3, 2.5, 1.0},
};

std::vector<ViewObservations> detectSequence(const BoardSpec& spec,
                                             const std::vector<Shot>& shots) {
  const Camera camera = testCamera();
  std::vector<ViewObservations> views;
  for (size_t k = 0; k < shots.size(); ++k) {
    const Shot& s = shots[k];
    const cv::Mat image =
        render(camera, spec, boardPose(camera, spec, s.coverage, s.tilt_x, s.tilt_y, s.roll),
               s.blur, s.noise, static_cast<int>(k));
    views.push_back(detectBoard(image, spec, {}, "frame " + std::to_string(k)));
  }
  return views;
}

void checkRejection(const BoardSpec& spec, const std::vector<Shot>& shots) {
  std::vector<ViewObservations> views = detectSequence(spec, shots);
  std::set<size_t> soft;
  for (size_t k = 0; k < shots.size(); ++k) {
    ASSERT_TRUE(views[k].found()) << views[k].source << ": " << views[k].failure;
    if (shots[k].blur >= 2.5) soft.insert(k);
  }
  const double reference = sharpnessReference(views);
  const int rejected = rejectSoftViews(views);
  std::printf("%s: reference sharpness %.3f, limit %.3f\n", toString(spec.type), reference,
              FocusOptions().min_relative_sharpness * reference);
  double sharp_ml_min = 1e9, sharp_ml_max = 0, sharp_s_min = 1e9, sharp_s_max = 0;
  double soft_s_max = 0;
  for (size_t k = 0; k < shots.size(); ++k) {
    const FocusMeasure& f = views[k].focus;
    std::printf(
        "  frame %2zu cover %.2f blur %.1f noise %.1f: sharpness %.3f (%d edge px), "
        "modified Laplacian %.2f, variance of Laplacian %.1f%s\n",
        k, shots[k].coverage, shots[k].blur, shots[k].noise, f.sharpness, f.edge_pixels,
        f.modified_laplacian, f.variance_of_laplacian, views[k].rejected ? "  REJECTED" : "");
    EXPECT_EQ(views[k].rejected, soft.count(k) == 1)
        << views[k].source << ": " << views[k].rejected_reason;
    if (soft.count(k)) {
      soft_s_max = std::max(soft_s_max, f.sharpness);
      EXPECT_NE(views[k].rejected_reason.find("soft"), std::string::npos);
    } else {
      sharp_ml_min = std::min(sharp_ml_min, f.modified_laplacian);
      sharp_ml_max = std::max(sharp_ml_max, f.modified_laplacian);
      sharp_s_min = std::min(sharp_s_min, f.sharpness);
      sharp_s_max = std::max(sharp_s_max, f.sharpness);
    }
  }
  EXPECT_EQ(rejected, static_cast<int>(soft.size()));
  std::printf(
      "sharp views: sharpness %.3f..%.3f (x%.2f), raw modified Laplacian %.2f..%.2f "
      "(x%.2f); softest kept / sharpest rejected = %.2f\n",
      sharp_s_min, sharp_s_max, sharp_s_max / sharp_s_min, sharp_ml_min, sharp_ml_max,
      sharp_ml_max / sharp_ml_min, sharp_s_min / soft_s_max);
  // The normalised measure barely moves with distance and tilt among in-focus views, while the
  // raw one moves more than the blur would: that is what lets a relative threshold work.
  EXPECT_LT(sharp_s_max / sharp_s_min, 1.6);
  EXPECT_GT(sharp_s_min, 1.5 * soft_s_max);
}

TEST(Focus, BlurredViewsRejectedSharpAndNoisyKeptChessboard) {
  checkRejection(synth::defaultBoard(BoardType::kChessboard), kSequence);
}

TEST(Focus, BlurredViewsRejectedSharpAndNoisyKeptAprilGrid) {
  // Six of the shots: the tags must stay decodable under the blur, so no far ones. (ChArUco's
  // 5x5 markers are lost at sigma 2.5 px: no board, nothing to judge.)
  const std::vector<Shot> shots = {kSequence[0], kSequence[1], kSequence[2],
                                   kSequence[4], kSequence[7], kSequence[11]};
  checkRejection(synth::defaultBoard(BoardType::kAprilGrid), shots);
}

TEST(Focus, UniformImageHasNoEdgesAndWholeImageRegionWhenNoPoints) {
  const cv::Mat flat(120, 160, CV_8UC1, cv::Scalar(90));
  const FocusMeasure f = measureFocus(flat, {});
  EXPECT_EQ(f.sharpness, 0.0);
  EXPECT_EQ(f.edge_pixels, 0);
  EXPECT_EQ(f.modified_laplacian, 0.0);
  EXPECT_EQ(f.variance_of_laplacian, 0.0);
  // A step edge: a vertical black/white boundary, sharp; sharpness ~2 (see focus.h).
  cv::Mat step(120, 160, CV_8UC1, cv::Scalar(20));
  step.colRange(80, 160).setTo(230);
  const FocusMeasure s = measureFocus(step, {});
  std::printf("ideal step: sharpness %.3f over %d edge px\n", s.sharpness, s.edge_pixels);
  EXPECT_NEAR(s.sharpness, 2.0, 0.05);
  EXPECT_THROW(measureFocus(cv::Mat(), {}), Error);
  EXPECT_THROW(measureFocus(cv::Mat(10, 10, CV_16UC1), {}), Error);
}

TEST(Focus, RejectionIgnoresViewsWithoutBoardAndValidatesOptions) {
  std::vector<ViewObservations> views(4);
  for (int k = 0; k < 3; ++k) {
    views[k].points.push_back({0, Eigen::Vector2d::Zero()});
    views[k].focus.sharpness = 1.0 + 0.1 * k;
  }
  views[3].focus.sharpness = 0.01;  // nothing found: not judged
  EXPECT_EQ(rejectSoftViews(views), 0);
  EXPECT_FALSE(views[3].rejected);
  views[0].focus.sharpness = 0.3;
  EXPECT_EQ(rejectSoftViews(views), 1);
  EXPECT_TRUE(views[0].rejected);
  FocusOptions bad;
  bad.min_relative_sharpness = 1.5;
  try {
    rejectSoftViews(views, bad);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("min_relative_sharpness"), std::string::npos);
  }
}

}  // namespace
}  // namespace previz::calib
