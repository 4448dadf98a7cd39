// The detector's own quad-search blur (tracking/detail/apriltag_blur.h) against libapriltag's:
// the same bytes as image_u8_gaussian_blur (Debian's apriltag-utils) on random images of many
// sizes and blurs, and the same detections, bit for bit, as libapriltag blurring itself, on the
// real tag photos of ../shared/data (outdoor, tag36h11) and a synthetic noisy frame of 24 tags,
// whole and in rectangles.
#include <gtest/gtest.h>

#include <cstdio>
#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/io.h"
#include "tracking/detail/apriltag_blur.h"
#include "tracking/detail/families.h"
#include "tracking/detect.h"

namespace previz::tracking {
namespace {

namespace fs = std::filesystem;

TEST(ApriltagBlur, KernelSizeAsLibapriltag) {
  // libapriltag: ksz = (int)(4 sigma), made odd; 1 = no blur.
  EXPECT_EQ(detail::apriltagBlurSize(0.2f), 1);
  EXPECT_EQ(detail::apriltagBlurSize(0.5f), 3);
  EXPECT_EQ(detail::apriltagBlurSize(0.8f), 3);
  EXPECT_EQ(detail::apriltagBlurSize(1.0f), 5);
  EXPECT_EQ(detail::apriltagBlurSize(1.3f), 5);
  EXPECT_EQ(detail::apriltagBlurSize(2.0f), 9);
  EXPECT_EQ(detail::apriltagBlurSize(3.3f), 13);
}

TEST(ApriltagBlur, SameBytesAsImageU8GaussianBlur) {
  cv::RNG rng(7);
  int compared = 0;
  detail::ApriltagBlurScratch scratch;  // one for every size, as a detector keeps it
  for (const float sigma : {0.5f, 0.8f, 1.0f, 1.3f, 1.6f, 2.0f, 3.3f}) {
    const int ksz = detail::apriltagBlurSize(sigma);
    for (const cv::Size size : {cv::Size(ksz + 1, ksz + 1), cv::Size(ksz + 1, 40), cv::Size(37, ksz + 2),
                                cv::Size(64, 48), cv::Size(203, 151), cv::Size(640, 9 + ksz)}) {
      cv::Mat image(size, CV_8UC1);
      rng.fill(image, cv::RNG::UNIFORM, 0, 256);
      // libapriltag's image with a stride of its own (rows padded), as apriltag_detector_detect
      // gets it from the detector.
      image_u8_t* ref = image_u8_create_stride(size.width, size.height, size.width + 13);
      for (int y = 0; y < size.height; ++y)
        std::copy(image.ptr<std::uint8_t>(y), image.ptr<std::uint8_t>(y) + size.width, ref->buf + y * ref->stride);
      image_u8_gaussian_blur(ref, static_cast<double>(sigma), ksz);
      cv::Mat ours = image.clone();
      ASSERT_TRUE(detail::apriltagBlur(ours, sigma, scratch)) << sigma << " " << size;
      int differ = 0;
      for (int y = 0; y < size.height; ++y)
        for (int x = 0; x < size.width; ++x) differ += ours.at<std::uint8_t>(y, x) != ref->buf[y * ref->stride + x];
      image_u8_destroy(ref);
      EXPECT_EQ(differ, 0) << "sigma " << sigma << ", " << size;
      ++compared;
    }
  }
  EXPECT_EQ(compared, 42);
}

TEST(ApriltagBlur, LeavesToLibapriltagWhatItDoesNotBlurTheSameWay) {
  cv::Mat image(20, 20, CV_8UC1, cv::Scalar(9));
  image.at<std::uint8_t>(10, 10) = 200;
  const cv::Mat before = image.clone();
  detail::ApriltagBlurScratch scratch;
  EXPECT_FALSE(detail::apriltagBlur(image, 0.0f, scratch));   // no blur asked
  EXPECT_FALSE(detail::apriltagBlur(image, 0.4f, scratch));   // kernel of 1
  cv::Mat small(5, 40, CV_8UC1, cv::Scalar(3));
  EXPECT_FALSE(detail::apriltagBlur(small, 1.3f, scratch));   // not taller than its kernel (5)
  EXPECT_EQ(cv::norm(image, before, cv::NORM_INF), 0.0);
  EXPECT_TRUE(detail::apriltagBlur(image, 0.8f, scratch));
  EXPECT_GT(cv::norm(image, before, cv::NORM_INF), 0.0);  // the spot spread
}

// Every detection field that comes from the image, compared exactly.
void expectSameDetections(const std::vector<TagDetection>& a, const std::vector<TagDetection>& b,
                          const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].family, b[i].family) << what;
    EXPECT_EQ(a[i].id, b[i].id) << what;
    EXPECT_EQ(a[i].hamming, b[i].hamming) << what;
    EXPECT_EQ(a[i].decision_margin, b[i].decision_margin) << what << " tag " << i;
    for (int q = 0; q < 4; ++q) EXPECT_EQ(a[i].corners_px[q], b[i].corners_px[q]) << what << " tag " << i;
    EXPECT_EQ(a[i].refined, b[i].refined) << what;
  }
}

// 24 tag36h11 tags, 24-110 px, tilted, on a grey 1280x720 frame with sensor noise (sigma 2).
cv::Mat syntheticTags() {
  cv::Mat frame(720, 1280, CV_8UC3, cv::Scalar(90, 110, 100));
  detail::FamilyPtr family = detail::createFamily("tag36h11");
  cv::RNG rng(3);
  for (int id = 0; id < 24; ++id) {
    image_u8_t* tag = apriltag_to_image(family.get(), id);
    cv::Mat small(tag->height, tag->width, CV_8UC1);
    for (int y = 0; y < tag->height; ++y)
      std::copy(tag->buf + y * tag->stride, tag->buf + y * tag->stride + tag->width, small.ptr<std::uint8_t>(y));
    image_u8_destroy(tag);
    cv::Mat white(small.rows + 4, small.cols + 4, CV_8UC1, cv::Scalar(255));  // quiet zone
    small.copyTo(white(cv::Rect(2, 2, small.cols, small.rows)));
    const double side = 24 + 86 * (id % 6) / 5.0;
    const cv::Point2f at(60 + 200 * (id % 6) + static_cast<float>(rng.uniform(0, 30)), 60 + 160 * (id / 6));
    const float n = static_cast<float>(white.cols);
    const std::vector<cv::Point2f> from = {{0, 0}, {n, 0}, {n, n}, {0, n}};
    std::vector<cv::Point2f> to;
    for (const cv::Point2f& p : from)
      to.emplace_back(at.x + p.x / n * side + rng.uniform(-0.15, 0.15) * side,
                      at.y + p.y / n * side + rng.uniform(-0.15, 0.15) * side);
    cv::Mat warped, mask;
    const cv::Mat H = cv::getPerspectiveTransform(from, to);
    cv::warpPerspective(white, warped, H, frame.size(), cv::INTER_AREA);
    cv::warpPerspective(cv::Mat(white.size(), CV_8UC1, cv::Scalar(255)), mask, H, frame.size(), cv::INTER_NEAREST);
    cv::Mat bgr;
    cv::cvtColor(warped, bgr, cv::COLOR_GRAY2BGR);
    bgr.copyTo(frame, mask);
  }
  cv::Mat noise(frame.size(), CV_16SC3);
  rng.fill(noise, cv::RNG::NORMAL, 0, 2);
  cv::Mat noisy;
  cv::add(frame, noise, noisy, cv::noArray(), CV_8UC3);
  return noisy;
}

TEST(ApriltagBlur, SameDetectionsAsLibapriltagBlurring) {
  const fs::path data = fs::path(PREVIZ_SHARED_DATA);
  const std::vector<fs::path> photos = {
      data / "apriltag-real" / "33369213973_9d9bb4cc96_c.jpg", data / "apriltag-real" / "34085369442_304b6bafd9_c.jpg",
      data / "apriltag-real" / "34139872896_defdb2f8d9_c.jpg", "synthetic"};
  size_t tags = 0;
  for (const fs::path& path : photos) {
    ASSERT_TRUE(path == "synthetic" || fs::exists(path)) << path << " (../shared/data)";
    const cv::Mat image = path == "synthetic" ? syntheticTags() : readImage(path, cv::IMREAD_COLOR);
    for (const float sigma : {0.8f, 1.3f}) {
      DetectorOptions o;
      o.auto_sigma = false;
      o.sigma = sigma;
      DetectorOptions lib = o;
      lib.library_blur = true;
      TagDetector ours(o), theirs(lib);
      const std::string what = path.filename().string() + " sigma " + std::to_string(sigma);
      const std::vector<TagDetection> a = ours.detect(image), b = theirs.detect(image);
      expectSameDetections(a, b, what + " whole");
      tags += a.size();
      std::printf("%s: %zu tags\n", what.c_str(), a.size());
      // Rectangles around the tags found (a tracker's regions), and one 7 px tall (left to
      // libapriltag: no blur of its own there).
      std::vector<Roi> rois;
      for (const TagDetection& d : a) {
        const cv::Point c(static_cast<int>(d.corners_px[0].x()), static_cast<int>(d.corners_px[0].y()));
        rois.emplace_back(c.x - 40, c.y - 40, 90, 90);
      }
      rois.emplace_back(0, 0, image.cols, 9);
      expectSameDetections(ours.detect(image, rois), theirs.detect(image, rois), what + " rectangles");
    }
  }
  // Tags were found (the photos 7-11 each, the synthetic frame 17-20 of its 24):
  // the comparison is not between two empty lists.
  EXPECT_GT(tags, 70u);
}

}  // namespace
}  // namespace previz::tracking
