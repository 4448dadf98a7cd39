#pragma once
// The previz_imgcodecs plugin (core/plugin/imgcodecs.cpp): OpenCV's imgcodecs for the image
// formats core/io.cpp does not read or write itself (TIFF, BMP, WebP, JPEG 2000, ... and the
// PNG / JPEG cases detail/image_codecs.h leaves to OpenCV). Loaded on the first such image
// (core/plugin.h): OpenCV's imgcodecs brings 140 shared libraries.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace previz::detail {

struct ImgcodecsPlugin {
  static constexpr int kVersion = 1;
  int version = kVersion;
  // cv::imread(path, flags); OpenCV's exceptions pass through.
  cv::Mat (*read)(const std::string& path, int flags) = nullptr;
  // cv::imencode(ext, image, bytes); OpenCV's exceptions pass through.
  bool (*encode)(const std::string& ext, const cv::Mat& image, std::vector<unsigned char>& bytes) = nullptr;
};

}  // namespace previz::detail
