// Compositor: CG distortion onto the lens (issue 7 item 2) and the per-pixel rules, on
// analytic images whose truth is known exactly.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "composite/compositor.h"
#include "core/distortion_maps.h"
#include "core/error.h"
#include "datasets/rigs.h"

namespace previz::composite {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr double kPeriod = 0.06;  // checker square, ideal normalized units

constexpr double kBlobSigma = 0.004;  // ideal normalized units (3 px at fx 750)

// A grid of Gaussian dots in ideal normalized coordinates, one per kPeriod: linear 0.05 + 0.75 g.
inline double dots(const Eigen::Vector2d& x) {
  const double gx = x.x() - kPeriod * std::round(x.x() / kPeriod), gy = x.y() - kPeriod * std::round(x.y() / kPeriod);
  return 0.05 + 0.75 * std::exp(-(gx * gx + gy * gy) / (2 * kBlobSigma * kBlobSigma));
}

// The dot grid as 'cam' films it: each pixel's footprint in ideal coordinates is the affine
// image of its square (centre through the inverse lens model, Jacobian of the forward model
// inverted: exact to far below a pixel over one pixel), box-filtered with 4 x 4 samples.
cv::Mat dotGrid(const Camera& cam) {
  cv::Mat img(cam.height, cam.width, CV_32FC3);
  const InverseDistortion inverse(cam.dist);
  const Eigen::Matrix2d Kinv = (Eigen::Matrix2d() << 1 / cam.fx, -cam.skew / (cam.fx * cam.fy), 0, 1 / cam.fy).finished();
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector2d x0 = inverse.solve(cam.pixelToNormalized(Eigen::Vector2d(u, v))).point;
      const Eigen::Matrix2d A = cam.distortJacobian(x0).inverse() * Kinv;  // pixel offset -> ideal
      double sum = 0;
      for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) sum += dots(x0 + A * Eigen::Vector2d((i + 0.5) / 4 - 0.5, (j + 0.5) / 4 - 0.5));
      const float value = static_cast<float>(sum / 16);
      img.at<cv::Vec3f>(v, u) = cv::Vec3f(value, value, value);
    }
  }
  return img;
}

// Intensity centroid above the background (the sRGB code of linear 0.05) in a 33 x 33 window
// (+-5 sigma: a truncated dot would pull the centroid towards the window's integer centre),
// re-centred twice.
cv::Point2f centroid(const cv::Mat& bgr8, cv::Point2f guess) {
  cv::Mat grey;
  cv::cvtColor(bgr8, grey, cv::COLOR_BGR2GRAY);
  const double background = 63.0;
  cv::Point2f c = guess;
  for (int it = 0; it < 3; ++it) {
    double sw = 0, sx = 0, sy = 0;
    const int cx = static_cast<int>(std::lround(c.x)), cy = static_cast<int>(std::lround(c.y));
    for (int y = cy - 16; y <= cy + 16; ++y)
      for (int x = cx - 16; x <= cx + 16; ++x) {
        if (x < 0 || y < 0 || x >= grey.cols || y >= grey.rows) continue;
        const double w = std::max(0.0, grey.at<uchar>(y, x) - background);
        sw += w;
        sx += w * x;
        sy += w * y;
      }
    if (sw > 0) c = cv::Point2f(static_cast<float>(sx / sw), static_cast<float>(sy / sw));
  }
  return c;
}

cv::Mat encodeLinear(const cv::Mat& rgb) {
  cv::Mat out(rgb.size(), CV_8UC3);
  for (int v = 0; v < rgb.rows; ++v)
    for (int u = 0; u < rgb.cols; ++u) {
      const cv::Vec3f c = rgb.at<cv::Vec3f>(v, u);
      for (int k = 0; k < 3; ++k) {
        const double l = std::clamp<double>(c[2 - k], 0, 1);
        const double e = l <= 0.0031308 ? 12.92 * l : 1.055 * std::pow(l, 1 / 2.4) - 0.055;
        out.at<cv::Vec3b>(v, u)[k] = static_cast<uchar>(std::lround(255 * e));
      }
    }
  return out;
}

void expectGridLands(const Camera& lens, double overscan, const char* what) {
  const Camera cg = idealPinhole(lens, overscan);
  const Compositor compositor(lens, cg);
  EXPECT_EQ(compositor.map().not_invertible, 0);
  EXPECT_EQ(compositor.outsideCg(), 0) << "the overscan covers the lens";

  // The compositor's own pass: alpha 0 everywhere, so the output is the CG through the lens.
  CompositeInputs in;
  in.foreground = cv::Mat(lens.height, lens.width, CV_8UC3, cv::Scalar(0, 255, 0));
  in.alpha = cv::Mat(lens.height, lens.width, CV_32FC1, cv::Scalar(0));
  in.actor_depth = cv::Mat(lens.height, lens.width, CV_32FC1, cv::Scalar(kInf));
  in.cg_color = dotGrid(cg);
  in.cg_depth = cv::Mat(cg.height, cg.width, CV_32FC1, cv::Scalar(5));
  const CompositeResult r = compositor.composite(in);
  const cv::Mat plate = encodeLinear(dotGrid(lens));  // the grid as the real lens films it

  // Truth: every grid dot's centre through the lens model.
  std::vector<cv::Point2f> truth;
  for (int j = -12; j <= 12; ++j)
    for (int i = -20; i <= 20; ++i) {
      const Eigen::Vector2d px = lens.normalizedToPixel(lens.distort(Eigen::Vector2d(i * kPeriod, j * kPeriod)));
      if (lens.inImage(px, 20)) truth.emplace_back(static_cast<float>(px.x()), static_cast<float>(px.y()));
    }
  ASSERT_GT(truth.size(), 100u);
  double max_truth = 0, max_plate = 0, sum_plate = 0, max_plate_truth = 0;
  std::vector<cv::Point2f> cg_corners, plate_corners;
  for (const cv::Point2f& p : truth) {
    cg_corners.push_back(centroid(r.bgr, p + cv::Point2f(0.7f, -0.6f)));
    plate_corners.push_back(centroid(plate, p + cv::Point2f(0.7f, -0.6f)));
  }
  for (size_t k = 0; k < truth.size(); ++k) {
    max_truth = std::max<double>(max_truth, cv::norm(cg_corners[k] - truth[k]));
    max_plate_truth = std::max<double>(max_plate_truth, cv::norm(plate_corners[k] - truth[k]));
    const double d = cv::norm(cg_corners[k] - plate_corners[k]);
    max_plate = std::max(max_plate, d);
    sum_plate += d;
  }
  std::printf("  %s: %zu dots, distorted CG grid vs plate grid: mean %.4f px, max %.4f px; vs the lens model: CG max "
              "%.4f px, plate max %.4f px\n",
              what, truth.size(), sum_plate / truth.size(), max_plate, max_truth, max_plate_truth);
  EXPECT_LE(max_plate, 0.1) << what;
  EXPECT_LE(max_truth, 0.1) << what;
}

TEST(CgDistortion, GridLandsOnThePlateGridWithinATenthOfAPixel) {
  expectGridLands(synth::mainCamera(960, 540), 0.1, "studio main lens 960x540");
  Camera strong = synth::mainCamera(960, 540);
  strong.name = "strong";
  strong.dist = Distortion{-0.22, 0.05, 0.0006, -0.0004, 0};
  expectGridLands(strong, 0.3, "k1 -0.22 lens with tangential terms");
}

struct Flat {
  CompositeInputs in;
  Camera lens, cg;
};

// A 64 x 48 lens without distortion and a CG pinhole of the same size: every lens pixel reads
// its own CG pixel.
Flat flat(float alpha, float actor_z, float cg_z) {
  Flat f;
  f.lens.name = "lens";
  f.lens.width = 64;
  f.lens.height = 48;
  f.lens.fx = f.lens.fy = 60;
  f.lens.cx = 31.5;
  f.lens.cy = 23.5;
  f.cg = f.lens;
  f.cg.name = "cg";
  f.in.foreground = cv::Mat(48, 64, CV_8UC3, cv::Scalar(30, 120, 200));
  f.in.alpha = cv::Mat(48, 64, CV_32FC1, cv::Scalar(alpha));
  f.in.actor_depth = cv::Mat(48, 64, CV_32FC1, cv::Scalar(actor_z));
  f.in.cg_color = cv::Mat(48, 64, CV_32FC3, cv::Scalar(0.5, 0.25, 0.1));  // R G B
  f.in.cg_depth = cv::Mat(48, 64, CV_32FC1, cv::Scalar(cg_z));
  return f;
}

TEST(Compositor, PlatePixelsPassUnresampledWhereTheActorIsInFront) {
  Flat f = flat(1.f, 2.0f, 3.0f);
  // Every 8-bit code must survive decode + encode.
  for (int u = 0; u < 64; ++u)
    for (int v = 0; v < 4; ++v) f.in.foreground.at<cv::Vec3b>(v, u) = cv::Vec3b(4 * u + v, 255 - 4 * u - v, (7 * u) % 256);
  const Compositor c(f.lens, f.cg, CompositeOptions{});
  const CompositeResult r = c.composite(f.in, true);
  EXPECT_EQ(cv::norm(r.bgr, f.in.foreground, cv::NORM_INF), 0);
  EXPECT_EQ(r.stats.actor_front_px, 64 * 48);
  EXPECT_EQ(r.stats.fallback_px, 0);
}

// Where there is no actor the pass takes a short path (the CG alone, read four floats at a time
// except at the CG's last pixel): it must give what the full path gives (debug layers on), and
// out-of-range CG values, NaN included, clamp (NaN to black) instead of indexing anywhere.
TEST(Compositor, CgAloneMatchesTheFullPathAndClampsBadCgValues) {
  Flat f = flat(0.f, 2.0f, 3.0f);
  cv::randu(f.in.cg_color, -0.2, 1.2);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  f.in.cg_color.at<cv::Vec3f>(0, 0) = cv::Vec3f(nan, 0.5f, nan);
  f.in.cg_color(cv::Rect(62, 46, 2, 2)).setTo(cv::Scalar(2.0, -1.0, 0.25));  // the block the last pixel blends
  const Compositor c(f.lens, f.cg, CompositeOptions{});
  const CompositeResult fast = c.composite(f.in, false), full = c.composite(f.in, true);
  EXPECT_EQ(cv::norm(fast.bgr, full.bgr, cv::NORM_INF), 0);
  EXPECT_EQ(fast.stats.actor_px, 0);
  EXPECT_EQ(fast.bgr.at<cv::Vec3b>(0, 0), cv::Vec3b(0, 188, 0));      // B G R: NaN -> 0
  EXPECT_EQ(fast.bgr.at<cv::Vec3b>(47, 63), cv::Vec3b(137, 0, 255));  // 0.25 -> 137
}

TEST(Compositor, CgInFrontWhereNearerAndSoftWithinTheBand) {
  CompositeOptions o;
  o.depth_band_m = 0.04;
  {
    Flat f = flat(1.f, 3.1f, 3.0f);  // actor 10 cm behind
    const CompositeResult r = Compositor(f.lens, f.cg, o).composite(f.in, true);
    EXPECT_EQ(r.stats.cg_front_px, 64 * 48);
    // CG linear (0.5, 0.25, 0.1) -> sRGB codes (188, 137, 89) in B G R order (89, 137, 188).
    EXPECT_EQ(r.bgr.at<cv::Vec3b>(10, 10), cv::Vec3b(89, 137, 188));
  }
  {
    Flat f = flat(1.f, 3.0f, 3.0f);  // equal depth: half way
    const CompositeResult r = Compositor(f.lens, f.cg, o).composite(f.in, true);
    EXPECT_NEAR(r.layer_alpha.at<float>(5, 5), 0.5, 1e-6);
  }
  {
    Flat f = flat(0.5f, 2.0f, 3.0f);  // soft key edge in front: alpha carries through
    const CompositeResult r = Compositor(f.lens, f.cg, o).composite(f.in, true);
    EXPECT_NEAR(r.layer_alpha.at<float>(5, 5), 0.5, 1e-6);
    EXPECT_EQ(r.layer_front.at<uchar>(5, 5), kFrontActor);
  }
  {
    Flat f = flat(1.f, 3.0f + 0.01f, 3.0f);  // 1 cm behind, a quarter into the 4 cm band
    const CompositeResult r = Compositor(f.lens, f.cg, o).composite(f.in, true);
    const double t = 0.25;
    EXPECT_NEAR(r.layer_alpha.at<float>(5, 5), t * t * (3 - 2 * t), 1e-4);
  }
}

TEST(Compositor, UnknownDepthTakesANeighbourElseFallsBackToFrontFlagged) {
  Flat f = flat(1.f, 3.5f, 3.0f);  // actor behind the CG where its depth is known
  f.in.actor_depth.colRange(0, 32).setTo(kInf);
  CompositeOptions o;
  o.edge_fill_px = 2;
  const CompositeResult r = Compositor(f.lens, f.cg, o).composite(f.in, true);
  // Columns 30, 31 are within 2 px of known depth (behind): filled; columns 0..29 fall back.
  EXPECT_EQ(r.stats.edge_filled_px, 2 * 48);
  EXPECT_EQ(r.stats.fallback_px, 30 * 48);
  EXPECT_EQ(r.layer_front.at<uchar>(20, 31), kFrontCg);
  EXPECT_EQ(r.layer_front.at<uchar>(20, 0), kFrontFallback);
  EXPECT_EQ(r.bgr.at<cv::Vec3b>(20, 0), cv::Vec3b(30, 120, 200));
}

TEST(Compositor, RejectsWrongInputsNamingThem) {
  Flat f = flat(1.f, 2.f, 3.f);
  const Compositor c(f.lens, f.cg);
  f.in.cg_depth = cv::Mat(10, 10, CV_32FC1, cv::Scalar(1));
  try {
    c.composite(f.in, false, "frame 7");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "cg_depth");
    EXPECT_NE(std::string(e.what()).find("frame 7"), std::string::npos) << e.what();
  }
  Camera distorted = f.cg;
  distorted.dist.k1 = 0.1;
  EXPECT_THROW(Compositor(f.lens, distorted), Error);
  CompositeOptions bad;
  bad.depth_band_m = -1;
  try {
    bad.validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "depth_band_m");
  }
}

}  // namespace
}  // namespace previz::composite
