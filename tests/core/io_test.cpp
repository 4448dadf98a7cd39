// File I/O: atomic writes, image errors, EXR (float channels, attributes), depth with +inf.
#include "core/io.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "scratch.h"

namespace fs = std::filesystem;

namespace previz {
namespace {

fs::path tmpDir(const std::string& name) {
  return test::scratchDir("io_test", name);
}

std::vector<std::string> folderEntries(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

TEST(Io, AtomicWriteCreatesParentsReplacesContentAndLeavesNoTemporary) {
  const fs::path dir = tmpDir("atomic");
  const fs::path p = dir / "a" / "b" / "file.txt";
  writeFileAtomic(p, "first");
  EXPECT_EQ(readTextFile(p), "first");
  writeFileAtomic(p, std::string("second\0binary", 13));
  EXPECT_EQ(readTextFile(p), std::string("second\0binary", 13));
  EXPECT_EQ(folderEntries(dir / "a" / "b"), std::vector<std::string>{"file.txt"});
}

TEST(Io, FailedWriteLeavesTheOldFileUntouched) {
  const fs::path dir = tmpDir("failed");
  const fs::path p = dir / "keep.txt";
  writeFileAtomic(p, "original");
  // The target's place is taken by a non-empty folder: rename fails, the temp is cleaned up.
  const fs::path blocked = dir / "blocked";
  fs::create_directories(blocked / "inside");
  EXPECT_THROW(writeFileAtomic(blocked, "x"), Error);
  EXPECT_EQ(readTextFile(p), "original");
  EXPECT_EQ(folderEntries(dir), (std::vector<std::string>{"blocked", "keep.txt"}));
  try {
    writeFileAtomic(blocked, "x");
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, blocked.string());
  }
}

TEST(Io, ReadImageNamesTheFileWhenMissingOrCorrupt) {
  const fs::path dir = tmpDir("images");
  cv::Mat img(32, 48, CV_8UC3);
  cv::randu(img, 0, 255);
  writeImageAtomic(dir / "ok.png", img);
  const cv::Mat back = readImage(dir / "ok.png");
  EXPECT_EQ(cv::norm(back, img, cv::NORM_INF), 0.0);

  try {
    readImage(dir / "missing.png");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, (dir / "missing.png").string());
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos);
  }
  // A PNG cut in the middle of its image data.
  const std::string bytes = readTextFile(dir / "ok.png");
  writeFileAtomic(dir / "truncated.png", bytes.substr(0, bytes.size() / 2));
  try {
    readImage(dir / "truncated.png");
    FAIL() << "truncated PNG decoded";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, (dir / "truncated.png").string());
    EXPECT_NE(std::string(e.what()).find("not a readable image"), std::string::npos) << e.what();
  }
  writeFileAtomic(dir / "text.png", "hello");
  EXPECT_THROW(readImage(dir / "text.png"), Error);
  EXPECT_THROW(writeImageAtomic(dir / "noext", img), Error);
}

TEST(Io, ExrRoundTripKeepsFloatsChannelOrderAndAttributes) {
  const fs::path dir = tmpDir("exr");
  ExrImage exr;
  exr.image.create(17, 23, CV_32FC3);
  cv::randn(exr.image, 0, 1000);
  exr.image.at<cv::Vec3f>(3, 4) = cv::Vec3f(std::numeric_limits<float>::infinity(), -0.0f, 1e-40f);
  exr.channels = {"Z", "A", "id"};  // not alphabetical: the order must survive
  exr.attributes = {{"previz:pixel_origin", "pixel (0,0) is the centre of the top-left pixel"},
                    {"previz:note", "any text"}};
  writeExr(dir / "a.exr", exr);
  const ExrImage back = readExr(dir / "a.exr");
  EXPECT_EQ(back.channels, exr.channels);
  EXPECT_EQ(back.attributes, exr.attributes);
  ASSERT_EQ(back.image.type(), CV_32FC3);
  EXPECT_EQ(std::memcmp(back.image.data, exr.image.data, exr.image.total() * exr.image.elemSize()), 0);

  // One channel, from a non-continuous ROI.
  cv::Mat big(40, 40, CV_32FC1);
  cv::randu(big, -5, 5);
  ExrImage roi{big(cv::Rect(3, 5, 20, 10)), {"Y"}, {}};
  writeExr(dir / "roi.exr", roi);
  const ExrImage back2 = readExr(dir / "roi.exr");
  EXPECT_EQ(cv::norm(back2.image, roi.image, cv::NORM_INF), 0.0);
  EXPECT_EQ(folderEntries(dir), (std::vector<std::string>{"a.exr", "roi.exr"}));
}

TEST(Io, HalfExrKeepsColourToHalfPrecisionAndReadsAsFloat) {
  const fs::path dir = tmpDir("exr_half");
  ExrImage exr;
  exr.image.create(31, 29, CV_32FC3);
  cv::randu(exr.image, 0.0, 4.0);
  exr.channels = {"R", "G", "B"};
  exr.half = true;
  writeExr(dir / "c.exr", exr);
  exr.half = false;
  writeExr(dir / "f.exr", exr);
  const ExrImage back = readExr(dir / "c.exr");
  ASSERT_EQ(back.image.type(), CV_32FC3);
  EXPECT_EQ(back.channels, exr.channels);
  // HALF has an 11-bit significand: relative error <= 2^-11 after round to nearest.
  double worst = 0;
  for (int y = 0; y < exr.image.rows; ++y)
    for (int x = 0; x < exr.image.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        const float a = exr.image.at<cv::Vec3f>(y, x)[c], b = back.image.at<cv::Vec3f>(y, x)[c];
        worst = std::max(worst, std::abs(double(a) - b) / std::max(1e-6, double(std::abs(a))));
      }
  EXPECT_LE(worst, std::ldexp(1.0, -11));
  EXPECT_GT(worst, 0.0);  // it really was stored as HALF
  EXPECT_LT(fs::file_size(dir / "c.exr"), fs::file_size(dir / "f.exr"));
}

TEST(Io, ExrErrorsNameTheFile) {
  const fs::path dir = tmpDir("exr_errors");
  EXPECT_THROW(readExr(dir / "none.exr"), Error);
  writeFileAtomic(dir / "bad.exr", "not an exr");
  try {
    readExr(dir / "bad.exr");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, (dir / "bad.exr").string());
  }
  ExrImage wrong{cv::Mat(4, 4, CV_8UC1, cv::Scalar(0)), {"Y"}, {}};
  EXPECT_THROW(writeExr(dir / "w.exr", wrong), Error);
  ExrImage names{cv::Mat(4, 4, CV_32FC2, cv::Scalar(0)), {"R"}, {}};
  EXPECT_THROW(writeExr(dir / "n.exr", names), Error);
}

// OpenEXR reads a known attribute type by the type, not by its declared size (a channel list up
// to its empty name, a preview's w x h pixels, a string vector's own lengths): a header whose
// declared sizes disagree with that is refused before OpenEXR sees it, naming the attribute
// (fuzz/corpus/exr/oom-string-attribute.exr: a channel list one byte short sent OpenEXR one
// byte past the walk, onto a 2 GB string).
TEST(Io, ExrHeaderWhoseSizesOpenExrWouldReadOtherwiseIsRefused) {
  const fs::path dir = tmpDir("exr_header_walk");
  ExrImage exr{cv::Mat(4, 6, CV_32FC3, cv::Scalar(0.25, 0.5, 0.75)), {"R", "G", "B"}, {{"previz:note", "x"}}};
  writeExr(dir / "good.exr", exr);
  ASSERT_NO_THROW(readExr(dir / "good.exr"));
  std::ifstream in(dir / "good.exr", std::ios::binary);
  const std::string good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto expectRefused = [&](const std::string& bytes, const std::string& file, const std::string& says) {
    writeFileAtomic(dir / file, bytes);
    try {
      readExr(dir / file);
      ADD_FAILURE() << file << " was read";
    } catch (const Error& e) {
      EXPECT_NE(e.message().find(says), std::string::npos) << e.message();
      EXPECT_EQ(e.context().file, (dir / file).string());
    }
  };
  const auto le32 = [](std::uint32_t v) {
    return std::string{static_cast<char>(v & 0xff), static_cast<char>(v >> 8 & 0xff), static_cast<char>(v >> 16 & 0xff),
                       static_cast<char>(v >> 24 & 0xff)};
  };
  // The channel list declaring one byte less than its channels take.
  const std::size_t chlist = good.find(std::string("chlist\0", 7));
  ASSERT_NE(chlist, std::string::npos);
  std::string short_list = good;
  short_list[chlist + 7] = static_cast<char>(static_cast<unsigned char>(short_list[chlist + 7]) - 1);
  expectRefused(short_list, "short_chlist.exr", "'channels' of type chlist is malformed");
  // A float declaring 5 bytes.
  const std::size_t aspect = good.find(std::string("float\0", 6));
  ASSERT_NE(aspect, std::string::npos);
  std::string wide_float = good;
  wide_float[aspect + 6] = 5;
  expectRefused(wide_float, "wide_float.exr", "where its type has 4");
  // Attributes put in front of the first one (the pixels after the header are never reached).
  const std::size_t first = 8;
  const auto withAttribute = [&](const std::string& name, const std::string& type, const std::string& value) {
    return good.substr(0, first) + name + '\0' + type + '\0' + le32(static_cast<std::uint32_t>(value.size())) +
           value + good.substr(first);
  };
  // A preview declaring 65535 x 65535 pixels (16 GiB) in 8 bytes.
  expectRefused(withAttribute("preview", "preview", le32(65535) + le32(65535)), "preview.exr",
                "its pixels are not its declared size");
  // A string vector whose one string claims 2 GB.
  expectRefused(withAttribute("names", "stringvector", le32(0x7fffffff) + "abc"), "strings.exr",
                "a string longer than the attribute");
}

TEST(Io, DepthExrUsesChannelZAndKeepsInfinity) {
  const fs::path dir = tmpDir("depth");
  cv::Mat depth(12, 16, CV_32FC1, cv::Scalar(std::numeric_limits<float>::infinity()));
  for (int y = 3; y < 9; ++y)
    for (int x = 4; x < 12; ++x) depth.at<float>(y, x) = 1.5f + 0.01f * x + 0.001f * y;
  writeDepthExr(dir / "d.exr", depth, {{"previz:camera", "main"}});
  const ExrImage raw = readExr(dir / "d.exr");
  EXPECT_EQ(raw.channels, std::vector<std::string>{"Z"});
  EXPECT_EQ(raw.attributes.at("previz:camera"), "main");
  EXPECT_TRUE(raw.attributes.count("previz:depth"));
  const cv::Mat back = readDepthExr(dir / "d.exr");
  int inf = 0;
  for (int y = 0; y < 12; ++y)
    for (int x = 0; x < 16; ++x) {
      const float a = depth.at<float>(y, x), b = back.at<float>(y, x);
      if (std::isinf(a)) {
        EXPECT_TRUE(std::isinf(b) && b > 0);
        ++inf;
      } else {
        EXPECT_EQ(a, b);
      }
    }
  EXPECT_EQ(inf, 12 * 16 - 6 * 8);
  ExrImage no_z{cv::Mat(2, 2, CV_32FC1, cv::Scalar(1)), {"Y"}, {}};
  writeExr(dir / "noz.exr", no_z);
  EXPECT_THROW(readDepthExr(dir / "noz.exr"), Error);
}

}  // namespace
}  // namespace previz
