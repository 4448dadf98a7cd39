// The renderer against exact truth: chessboard corners where Camera::project puts them, pixel
// rays equal to Camera::unproject, depth/mask equal to the true actor mesh, and bit-identical
// output for any thread count.
#include "datasets/render.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <set>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/board.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace previz::synth {
namespace {

// A strongly distorted small camera (barrel with a positive k2 and some decentring), so that
// a wrong distortion direction, a half-pixel offset or a wrong inverse all show.
Camera distortedCamera() {
  Camera c;
  c.name = "test";
  c.width = 640;
  c.height = 360;
  c.fx = 452.0;
  c.fy = 452.0;
  c.cx = 322.7;
  c.cy = 177.6;
  c.dist.k1 = -0.22;
  c.dist.k2 = 0.05;
  c.dist.p1 = 0.0007;
  c.dist.p2 = -0.0005;
  return c;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

TEST(Render, SamplePatternIsStratifiedInCellsRowsAndColumns) {
  for (int n : {2, 3, 4}) {
    const std::vector<Eigen::Vector2d> p = samplePattern(n * n);
    ASSERT_EQ(static_cast<int>(p.size()), n * n);
    std::set<int> cells, columns, rows;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& s : p) {
      ASSERT_GT(s.minCoeff(), -0.5);
      ASSERT_LT(s.maxCoeff(), 0.5);
      const double x = s.x() + 0.5, y = s.y() + 0.5;
      cells.insert(static_cast<int>(x * n) + n * static_cast<int>(y * n));
      columns.insert(static_cast<int>(x * n * n));
      rows.insert(static_cast<int>(y * n * n));
      mean += s;
    }
    EXPECT_EQ(static_cast<int>(cells.size()), n * n) << "n = " << n;
    EXPECT_EQ(static_cast<int>(columns.size()), n * n) << "n = " << n;
    EXPECT_EQ(static_cast<int>(rows.size()), n * n) << "n = " << n;
    EXPECT_LT(mean.norm() / p.size(), 1e-12);
  }
  // Non-square counts: one sample per column, centred.
  const std::vector<Eigen::Vector2d> p = samplePattern(6);
  std::set<int> columns;
  for (const Eigen::Vector2d& s : p) columns.insert(static_cast<int>((s.x() + 0.5) * 6));
  EXPECT_EQ(columns.size(), 6u);
}

TEST(Render, PixelRayEqualsUnprojectAndProjectsBackBelowNanoPixel) {
  const Camera camera = distortedCamera();
  double worst_angle = 0, worst_px = 0;
  for (int i = 0; i <= 40; ++i) {
    for (int j = 0; j <= 24; ++j) {
      const Eigen::Vector2d px(-0.5 + i * camera.width / 40.0, -0.5 + j * camera.height / 24.0);
      Eigen::Vector3d ray;
      ASSERT_TRUE(pixelRay(camera, px, ray)) << px.transpose();
      const std::optional<Eigen::Vector3d> reference = camera.unproject(px);
      ASSERT_TRUE(reference.has_value());
      worst_angle = std::max(worst_angle, (ray - *reference).norm());  // radians, small angle
      const std::optional<Eigen::Vector2d> back = camera.project(ray);
      ASSERT_TRUE(back.has_value());
      worst_px = std::max(worst_px, (*back - px).norm());
    }
  }
  std::printf("pixelRay vs unproject: worst angle %.3g rad, reprojection %.3g px\n", worst_angle,
              worst_px);
  EXPECT_LT(worst_angle, 1e-12);
  EXPECT_LT(worst_px, 1e-9);
}

// The same through a studio fisheye witness (Kannala-Brandt, 160 degrees diagonal): the
// renderer's Newton on lens_model.h's fisheye against Camera::unproject, corners included.
TEST(Render, FisheyePixelRayEqualsUnprojectAndProjectsBack) {
  const Camera camera = witnessCamera(2, 8, 3, 1280, 720, true).camera;
  ASSERT_EQ(camera.dist.model, LensModel::kKannalaBrandt);
  double worst_angle = 0, worst_px = 0, widest = 0;
  for (int i = 0; i <= 40; ++i) {
    for (int j = 0; j <= 24; ++j) {
      const Eigen::Vector2d px(-0.5 + i * camera.width / 40.0, -0.5 + j * camera.height / 24.0);
      Eigen::Vector3d ray;
      ASSERT_TRUE(pixelRay(camera, px, ray)) << px.transpose();
      const std::optional<Eigen::Vector3d> reference = camera.unproject(px);
      ASSERT_TRUE(reference.has_value());
      worst_angle = std::max(worst_angle, (ray - *reference).norm());
      widest = std::max(widest, std::acos(reference->z()));
      const std::optional<Eigen::Vector2d> back = camera.project(ray);
      ASSERT_TRUE(back.has_value());
      worst_px = std::max(worst_px, (*back - px).norm());
    }
  }
  std::printf("fisheye pixelRay vs unproject: worst angle %.3g rad, reprojection %.3g px, corner ray %.1f deg off axis\n",
              worst_angle, worst_px, widest * 180 / M_PI);
  EXPECT_GE(2 * widest * 180 / M_PI, 150.0);
  EXPECT_LT(worst_angle, 1e-12);
  EXPECT_LT(worst_px, 1e-9);
}

// Renders intrinsics-preset frames of a chessboard without blur or noise, detects the corners
// with OpenCV and compares them with Camera::project of the true corners. Checks the renderer,
// the camera model and the pixel-centre convention together (a half-pixel slip alone gives
// 0.7 px; ignoring distortion gives several px).
//
// The refinement runs in linear light. cornerSubPix on the 8-bit sRGB image is biased on a
// box-filtered (area-sampled) render: an exactly area-sampled chessboard made without previz
// (analytic coverage) gives 0.04 px median at roll 0 and ~0.1 px at rolls of 0.05–0.15 rad,
// because the sRGB curve makes each edge's profile asymmetric and, on near-axis edges, the
// sub-pixel phase hardly varies along the edge so the bias does not average out. Decoding to
// linear and a light symmetric pre-filter (which cannot move an X-junction's saddle) brings the
// same reference to ~0.02 px, so what remains here measures the renderer and the camera model.
TEST(Render, ChessboardCornersMatchTruthWithinFiveHundredthsPixel) {
  const Camera camera = distortedCamera();
  const BoardSpec spec = defaultBoard(BoardType::kChessboard);
  StudioConfig config;
  config.with_actor = false;
  config.with_prop = false;
  const Studio studio(config);
  const Pose T_world_cam = mainCameraPose(0.0, 1.0, false);
  const cv::Size pattern(spec.cols - 1, spec.rows - 1);
  const std::vector<BoardPoint> points = boardPoints(spec);
  const cv::TermCriteria criteria(cv::TermCriteria::EPS | cv::TermCriteria::COUNT, 100, 1e-5);

  RenderOptions options;
  options.samples_per_pixel = 16;
  std::vector<double> errors, errors_srgb;
  int frames_detected = 0;
  const int frames = 8;
  for (int f = 0; f < frames; ++f) {
    const Pose T_cam_board = intrinsicsBoardPose(camera, spec, f, 7);
    Scene scene = studio.sceneAt(0.0, kLayerStage);
    scene.add(makeBoard(spec, T_world_cam * T_cam_board));
    const RenderedView view = renderView(camera, T_world_cam, scene, options);
    cv::Mat gray;
    cv::cvtColor(view.bgr, gray, cv::COLOR_BGR2GRAY);
    std::vector<cv::Point2f> found;
    if (!cv::findChessboardCorners(gray, pattern, found,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE)) {
      std::printf("frame %d: board not detected\n", f);
      continue;
    }
    ++frames_detected;
    std::vector<cv::Point2f> corners = found, corners_srgb = found;
    cv::cornerSubPix(gray, corners_srgb, cv::Size(4, 4), cv::Size(-1, -1), criteria);
    cv::Mat linear(gray.size(), CV_32F);
    for (int v = 0; v < gray.rows; ++v) {
      for (int u = 0; u < gray.cols; ++u) {
        linear.at<float>(v, u) = static_cast<float>(srgbDecode(gray.at<std::uint8_t>(v, u) / 255.0));
      }
    }
    cv::GaussianBlur(linear, linear, cv::Size(0, 0), 1.0);
    cv::cornerSubPix(linear, corners, cv::Size(5, 5), cv::Size(-1, -1), criteria);

    // Truth corners; the detector's ordering is ambiguous (half turns), so match each detected
    // corner to the nearest truth corner — corners are >= 10 px apart, errors are << 1 px.
    std::vector<Eigen::Vector2d> truth;
    for (const BoardPoint& p : points) {
      const std::optional<Eigen::Vector2d> px = camera.project(T_cam_board * p.p_board);
      ASSERT_TRUE(px.has_value());
      truth.push_back(*px);
    }
    auto match = [&](const std::vector<cv::Point2f>& detected, std::vector<double>& out) {
      std::set<size_t> used;
      for (const cv::Point2f& c : detected) {
        size_t best = 0;
        double best_d = 1e9;
        for (size_t i = 0; i < truth.size(); ++i) {
          const double d = (truth[i] - Eigen::Vector2d(c.x, c.y)).norm();
          if (d < best_d) {
            best_d = d;
            best = i;
          }
        }
        EXPECT_TRUE(used.insert(best).second) << "two detections matched corner " << best;
        out.push_back(best_d);
      }
    };
    std::vector<double> frame_errors;
    match(corners, frame_errors);
    match(corners_srgb, errors_srgb);
    std::printf("frame %d: %zu corners, median %.4f px, max %.4f px\n", f, frame_errors.size(),
                median(frame_errors), *std::max_element(frame_errors.begin(), frame_errors.end()));
    errors.insert(errors.end(), frame_errors.begin(), frame_errors.end());
  }
  ASSERT_GE(frames_detected, frames - 2) << "too few frames detected to judge";
  const double med = median(errors);
  const double worst = *std::max_element(errors.begin(), errors.end());
  std::printf("all frames: %zu corners, median %.4f px, max %.4f px (cornerSubPix on the sRGB "
              "image: median %.4f px, max %.4f px)\n",
              errors.size(), med, worst, median(errors_srgb),
              *std::max_element(errors_srgb.begin(), errors_srgb.end()));
  EXPECT_LE(med, 0.05);
  EXPECT_LE(worst, 0.2);
}

TEST(Render, DepthIsMetricZAlongTheAxisForAKnownPlane) {
  // A board facing the camera squarely at z = 1.5 m fills the middle of the image: every
  // pixel whose centre ray hits it has depth 1.5 exactly (z, not ray length).
  const Camera camera = distortedCamera();
  const BoardSpec spec = defaultBoard(BoardType::kChessboard);
  Pose T_cam_board = Pose::Identity();
  const Eigen::Vector2d size = spec.size_m();
  T_cam_board.translation() = Eigen::Vector3d(-0.5 * size.x(), -0.5 * size.y(), 1.5);
  Scene scene;
  scene.add(makeBoard(spec, T_cam_board));
  RenderOptions options;
  const RenderedView view = renderView(camera, Pose::Identity(), scene, options);
  int board_pixels = 0, empty_pixels = 0;
  double worst = 0;
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      const float z = view.depth.at<float>(v, u);
      const auto cls = static_cast<ObjectClass>(view.labels.at<std::uint8_t>(v, u));
      if (cls == ObjectClass::kBoard) {
        ++board_pixels;
        worst = std::max(worst, std::abs(z - 1.5));
      } else {
        ASSERT_EQ(cls, ObjectClass::kNone);
        ASSERT_TRUE(std::isinf(z) && z > 0);
        ++empty_pixels;
      }
      ASSERT_EQ(view.mask.at<std::uint8_t>(v, u), 0);
    }
  }
  EXPECT_GT(board_pixels, 1000);
  EXPECT_GT(empty_pixels, 1000);
  EXPECT_LT(worst, 1e-5);  // float storage of 1.5 m
}

// Motion blur samples the shutter in time: with a static camera only what moves may change,
// and a moving actor does change the pixels it sweeps.
TEST(Render, MotionBlurChangesOnlyThePixelsTheActorSweeps) {
  StudioConfig config;
  config.with_prop = false;
  const Studio studio(config);
  const RigCamera rc = witnessCamera(1, 8, 3, 320, 180);
  const double t = 2.0, half_open = 0.5 / 24.0;  // walking; a 1/24 s shutter
  std::vector<Scene> scenes;
  for (int i = 0; i < 4; ++i) scenes.push_back(studio.sceneAt(t + half_open * ((i + 0.5) / 2 - 1), kLayerActor));
  const Scene centre = studio.sceneAt(t, kLayerActor);
  std::vector<ShutterSample> shutter;
  for (const Scene& s : scenes) shutter.push_back({&s, rc.T_world_cam});
  RenderOptions options;
  const RenderedView sharp = renderView(rc.camera, rc.T_world_cam, centre, options);
  const RenderedView blurred = renderView(rc.camera, shutter, {&centre, rc.T_world_cam}, options);
  // Where the actor is at any instant (pixel-centre masks), grown by a pixel for the samples.
  cv::Mat swept = cv::Mat::zeros(sharp.mask.size(), CV_8U);
  for (const Scene& s : scenes) {
    swept |= renderView(rc.camera, rc.T_world_cam, s, options).mask;
  }
  cv::dilate(swept, swept, cv::Mat::ones(3, 3, CV_8U));
  int changed_inside = 0, changed_outside = 0;
  for (int v = 0; v < sharp.bgr.rows; ++v) {
    for (int u = 0; u < sharp.bgr.cols; ++u) {
      const bool changed = sharp.bgr.at<cv::Vec3b>(v, u) != blurred.bgr.at<cv::Vec3b>(v, u);
      (swept.at<std::uint8_t>(v, u) ? changed_inside : changed_outside) += changed;
    }
  }
  std::printf("motion blur: %d px changed where the actor sweeps, %d elsewhere\n", changed_inside,
              changed_outside);
  EXPECT_EQ(changed_outside, 0);
  EXPECT_GT(changed_inside, 20);
  // Truth layers come from the frame time itself.
  EXPECT_TRUE(std::equal(sharp.mask.datastart, sharp.mask.dataend, blurred.mask.datastart));
}

class RenderReproducibility : public ::testing::Test {
 protected:
  static RenderedView render(std::uint64_t seed, int threads, double noise) {
    StudioConfig config;
    const Studio studio(config);
    static const RigCamera rc = witnessCamera(0, 8, 3, 320, 180);
    const Scene scene = studio.sceneAt(1.0, kLayersPlate);
    RenderOptions options;
    options.seed = seed;
    options.threads = threads;
    options.noise_sigma = noise;
    options.blur_sigma_px = 0.8;
    options.camera_index = 2;
    options.frame = 5;
    return renderView(rc.camera, rc.T_world_cam, scene, options);
  }
  static bool identical(const cv::Mat& a, const cv::Mat& b) {
    return a.size() == b.size() && a.type() == b.type() &&
           std::equal(a.datastart, a.dataend, b.datastart);
  }
};

TEST_F(RenderReproducibility, SameSeedAndAnyThreadCountGiveIdenticalBits) {
  const RenderedView one = render(11, 1, 3.0);
  const RenderedView two = render(11, 2, 3.0);
  const RenderedView again = render(11, 2, 3.0);
  EXPECT_TRUE(identical(one.bgr, two.bgr));
  EXPECT_TRUE(identical(two.bgr, again.bgr));
  EXPECT_TRUE(identical(one.depth, two.depth));
  EXPECT_TRUE(identical(one.labels, two.labels));
  EXPECT_TRUE(identical(one.mask, two.mask));
}

TEST_F(RenderReproducibility, AnotherSeedChangesOnlyTheNoise) {
  const RenderedView a = render(11, 2, 3.0);
  const RenderedView b = render(12, 2, 3.0);
  const RenderedView clean_a = render(11, 2, 0.0);
  const RenderedView clean_b = render(12, 2, 0.0);
  cv::Mat diff;
  cv::absdiff(a.bgr, b.bgr, diff);
  const double changed = cv::countNonZero(diff.reshape(1)) / static_cast<double>(diff.total() * 3);
  std::printf("fraction of channels changed by the seed: %.3f\n", changed);
  EXPECT_GT(changed, 0.5);  // sigma 3: P(same rounded value) ~ 0.1 per channel
  EXPECT_TRUE(identical(clean_a.bgr, clean_b.bgr));  // the pattern never depends on the seed
}

}  // namespace
}  // namespace previz::synth
