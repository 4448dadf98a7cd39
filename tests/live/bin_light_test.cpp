// live/bin_light.h: the witness plates' binning (FrameLoopOptions::witness_bin) against its
// definition, computed here pixel by pixel: the 16-pixel bin-2 loop and the general one.
#include "live/bin_light.h"

#include "core/error.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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
