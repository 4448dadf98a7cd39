// Issue 33 item 3: the tag detector's blur chosen per camera from the frame's own noise
// (DetectorOptions::auto_sigma; tracking/detect.h estimateNoise, sigmaForNoise). The estimator
// against known noise, on flat and on busy images; the blur it chooses on the real photos and
// on the studio's frames is checked where those are detected (detect_real_test.cpp,
// accuracy_test.cpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include <opencv2/imgproc.hpp>

#include "core/io.h"
#include "tracking/detect.h"

namespace previz::tracking {
namespace {

// A ramp with a step (smooth content, few edges) or a 6 px checkerboard (busy: a third of the
// pixels next to an edge), plus Gaussian noise of sigma per channel, rounded to 8 bits.
cv::Mat noisyImage(double sigma, int channels, bool busy, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, sigma);
  cv::Mat img(480, 640, CV_8UC(channels));
  for (int v = 0; v < img.rows; ++v)
    for (int u = 0; u < img.cols; ++u) {
      const double base = busy ? (((u / 6) + (v / 6)) % 2 ? 190.0 : 50.0) : 60 + 0.2 * u + 0.1 * v + 40 * (u > 320);
      for (int c = 0; c < channels; ++c)
        img.ptr<uint8_t>(v)[u * channels + c] = cv::saturate_cast<uint8_t>(std::lround(base + noise(rng)));
    }
  return img;
}

// The grey of a BGR image whose channels carry independent noise sigma has 0.669 sigma (OpenCV's
// weights 0.114, 0.587, 0.299); rounding adds 0.29 levels in quadrature (uniform quantisation).
TEST(DetectorAuto, NoiseEstimateWithinTenPercentOfTheTruth) {
  for (int channels : {1, 3})
    for (double sigma : {1.0, 2.0, 3.0, 5.0}) {
      const double grey = channels == 1 ? sigma : sigma * std::sqrt(0.114 * 0.114 + 0.587 * 0.587 + 0.299 * 0.299);
      const double truth = std::sqrt(grey * grey + (channels == 1 ? 1.0 / 12 : 0.0));
      const cv::Mat img = noisyImage(sigma, channels, false, 7);
      const double est = estimateNoise(img, cv::Rect(0, 0, img.cols, img.rows));
      std::printf("%d channel(s), sigma %.1f: grey noise %.3f, estimated %.3f\n", channels, sigma, truth, est);
      EXPECT_NEAR(est, truth, 0.1 * truth) << channels << " channel(s), sigma " << sigma;
    }
}

// Edges are not noise: on the checkerboard (every third pixel next to a 140-level step) the
// median-based estimate stays within 20 % (Immerkaer's mean |response| reads several times more).
TEST(DetectorAuto, EdgesAreNotCountedAsNoise) {
  for (double sigma : {0.0, 2.0}) {
    const cv::Mat img = noisyImage(sigma, 1, true, 11);
    const double est = estimateNoise(img, cv::Rect(0, 0, img.cols, img.rows));
    std::printf("checkerboard, sigma %.1f: estimated %.3f\n", sigma, est);
    if (sigma == 0)
      EXPECT_LT(est, 0.3);
    else
      EXPECT_NEAR(est, sigma, 0.2 * sigma);
  }
}

TEST(DetectorAuto, BlurForNoise) {
  EXPECT_EQ(sigmaForNoise(0.0), 0.0f);
  EXPECT_EQ(sigmaForNoise(0.5), 0.0f);   // the real JPEG photos
  EXPECT_NEAR(sigmaForNoise(1.29), 0.8f, 0.01f);  // the studio's witnesses (2 levels a channel)
  EXPECT_EQ(sigmaForNoise(10.0), 1.6f);
  EXPECT_EQ(sigmaForNoise(std::nan("")), 0.0f);
}

// The detector reports what it measured and chose; a fixed blur is reported as such.
TEST(DetectorAuto, TheDetectorSaysWhatItChose) {
  const cv::Mat noisy = noisyImage(2.0, 3, false, 5), clean = noisyImage(0.0, 3, false, 5);
  TagDetector detector{DetectorOptions{}};
  detector.detect(noisy);
  EXPECT_NEAR(detector.lastNoise(), 1.34, 0.13);
  EXPECT_NEAR(detector.lastSigma(), 0.8f, 0.08f);
  detector.detect(clean);
  EXPECT_LT(detector.lastNoise(), 0.5);
  EXPECT_EQ(detector.lastSigma(), 0.0f);
  // A search of regions only keeps the camera's last whole-frame measure.
  detector.detect(noisy);
  detector.detect(clean, {cv::Rect(10, 10, 100, 100)});
  EXPECT_NEAR(detector.lastSigma(), 0.8f, 0.08f);
  DetectorOptions fixed;
  fixed.auto_sigma = false;
  fixed.sigma = 0.3f;
  TagDetector manual(fixed);
  manual.detect(noisy);
  EXPECT_EQ(manual.lastNoise(), -1.0);
  EXPECT_EQ(manual.lastSigma(), 0.3f);
}

}  // namespace
}  // namespace previz::tracking
