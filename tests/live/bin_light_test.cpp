// live/bin_light.h: the witness plates' binning (FrameLoopOptions::witness_bin) against its
// definition, computed here pixel by pixel: the 16-pixel bin-2 loop and the general one.
#include "live/bin_light.h"

#include "core/error.h"
#include "core/io.h"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

namespace previz::live {
namespace {

cv::Mat definition(const cv::Mat& src, int bin, cv::Size size) {
  cv::Mat out(size, CV_8UC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      for (int ch = 0; ch < 3; ++ch) {
        long long sum = 0;
        for (int j = 0; j < bin; ++j)
          for (int i = 0; i < bin; ++i) {
            const int v = src.at<cv::Vec3b>(std::min(y * bin + j, src.rows - 1), std::min(x * bin + i, src.cols - 1))[ch];
            sum += v * v;
          }
        const long long mean = (sum + bin * bin / 2) / (bin * bin);
        out.at<cv::Vec3b>(y, x)[ch] = static_cast<uchar>(std::lround(std::sqrt(static_cast<double>(mean))));
      }
  return out;
}

void expectDefinition(const cv::Mat& src, int bin, cv::Size size, const std::string& what) {
  cv::Mat got;
  binLight(src, bin, size, got);
  const cv::Mat want = definition(src, bin, size);
  ASSERT_EQ(got.size(), size) << what;
  ASSERT_EQ(got.type(), CV_8UC3) << what;
  cv::Mat diff;
  cv::absdiff(got, want, diff);
  EXPECT_EQ(cv::countNonZero(diff.reshape(1)), 0) << what << ": bin " << bin << ", " << src.cols << "x" << src.rows
                                                  << " -> " << size.width << "x" << size.height;
}

TEST(BinLight, EveryBinAndSizeGivesTheDefinitionsBytes) {
  cv::RNG rng(31);
  for (const cv::Size plate : {cv::Size(1280, 720), cv::Size(641, 361), cv::Size(67, 5), cv::Size(1, 1), cv::Size(3, 2)}) {
    cv::Mat src(plate, CV_8UC3);
    rng.fill(src, cv::RNG::UNIFORM, 0, 256);
    for (int bin = 1; bin <= 4; ++bin) {
      const cv::Size up((plate.width + bin - 1) / bin, (plate.height + bin - 1) / bin);
      const cv::Size down(std::max(1, plate.width / bin), std::max(1, plate.height / bin));
      expectDefinition(src, bin, up, "rounded up (the last block repeats the edge)");
      expectDefinition(src, bin, down, "rounded down (the edge left over)");
    }
  }
}

// Every mean of four squared codes the 16-pixel loop can meet, and its square root's rounding
// next to the ties: blocks of codes a, a, b, b for every pair (a, b).
TEST(BinLight, TwoByTwoOverEveryPairOfCodes) {
  cv::Mat src(2, 2 * 256 * 256, CV_8UC3);
  for (int a = 0; a < 256; ++a)
    for (int b = 0; b < 256; ++b) {
      const int x = 2 * (a * 256 + b);
      src.at<cv::Vec3b>(0, x) = src.at<cv::Vec3b>(1, x) = cv::Vec3b(a, b, 255 - a);
      src.at<cv::Vec3b>(0, x + 1) = src.at<cv::Vec3b>(1, x + 1) = cv::Vec3b(b, a, (a + b) / 2);
    }
  expectDefinition(src, 2, cv::Size(src.cols / 2, 1), "every code pair");
}

TEST(BinLight, AveragesLightNotCodes) {
  cv::Mat src(2, 2, CV_8UC3, cv::Scalar(150, 150, 150));
  src.row(1).setTo(cv::Scalar(40, 40, 40));
  cv::Mat out;
  binLight(src, 2, cv::Size(1, 1), out);
  EXPECT_EQ(out.at<cv::Vec3b>(0, 0), cv::Vec3b(110, 110, 110));  // codes' mean 95, sRGB's light 112
  src.setTo(cv::Scalar(7, 200, 99));
  binLight(src, 2, cv::Size(1, 1), out);
  EXPECT_EQ(out.at<cv::Vec3b>(0, 0), cv::Vec3b(7, 200, 99));  // a uniform block gives its code back
}

// Real photos (../shared/data/apriltag-real: JPEG colour, odd sizes), binned 2 x 2: the
// definition's bytes, and beside OpenCV's area resize of the squared codes (float) with the
// square root rounded after it, which differs only where rounding the mean first moves the
// root across a half: by one code at most, on few values.
TEST(BinLight, RealPhotosGiveTheDefinitionsBytesAndOpenCvsAreaMeanWithinOneCode) {
  const std::filesystem::path data = std::filesystem::path(PREVIZ_SHARED_DATA) / "apriltag-real";
  for (const char* name : {"33369213973_9d9bb4cc96_c.jpg", "34085369442_304b6bafd9_c.jpg",
                           "34139872896_defdb2f8d9_c.jpg"}) {
    ASSERT_TRUE(std::filesystem::exists(data / name)) << data / name << " (../shared/data)";
    const cv::Mat photo = readImage(data / name, 1 /* colour */);
    const cv::Size half(photo.cols / 2, photo.rows / 2);
    expectDefinition(photo, 2, half, name);
    cv::Mat ours, squares, mean, opencv;
    binLight(photo, 2, half, ours);
    photo(cv::Rect(0, 0, 2 * half.width, 2 * half.height)).convertTo(squares, CV_32FC3);
    cv::resize(squares.mul(squares), mean, half, 0, 0, cv::INTER_AREA);
    cv::sqrt(mean, mean);
    mean.convertTo(opencv, CV_8UC3);  // rounded to nearest
    cv::Mat diff;
    cv::absdiff(ours, opencv, diff);
    double max_diff = 0;
    cv::minMaxLoc(diff.reshape(1), nullptr, &max_diff);
    const int differing = cv::countNonZero(diff.reshape(1));
    std::printf("%s %dx%d: %d of %d values differ from OpenCV's area mean of code^2 (max %g)\n", name, photo.cols,
                photo.rows, differing, 3 * half.area(), max_diff);
    EXPECT_LE(max_diff, 1.0) << name;
    EXPECT_LT(differing, 3 * half.area() / 1000) << name;  // measured: 70-145 of 318402
  }
}

// A plate binning cannot read (another pixel type, nothing) or a size it cannot fill: an Error
// saying which, not an OpenCV assertion.
TEST(BinLight, RefusesWhatItCannotBinSayingWhy) {
  cv::Mat out;
  auto message = [&](const cv::Mat& src, int bin, cv::Size size) {
    try {
      binLight(src, bin, size, out);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(cv::Mat(4, 4, CV_16UC3, cv::Scalar(0)), 2, cv::Size(2, 2)).find("8-bit BGR (got CV_16UC3)"),
            std::string::npos);
  EXPECT_NE(message(cv::Mat(), 2, cv::Size(2, 2)).find("an empty image"), std::string::npos);
  EXPECT_NE(message(cv::Mat(4, 4, CV_8UC3, cv::Scalar(0)), 2, cv::Size(3, 2)).find("4x4 cannot bin 2 x 2 into 3x2"),
            std::string::npos);
  EXPECT_NE(message(cv::Mat(4, 4, CV_8UC3, cv::Scalar(0)), 0, cv::Size(2, 2)).find("cannot bin 0 x 0"),
            std::string::npos);
}

}  // namespace
}  // namespace previz::live
