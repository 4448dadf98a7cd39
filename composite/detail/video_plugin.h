#pragma once
// The previz_composite_video plugin (composite/plugin/video.cpp): OpenCV's cv::VideoWriter for
// the composite's video (output.h), loaded when the first video frame is written
// (core/plugin.h): OpenCV's videoio brings 244 shared libraries.
#include <memory>
#include <string>

#include <opencv2/core.hpp>

namespace previz::composite::detail {

class VideoOut {
 public:
  virtual ~VideoOut() = default;
  virtual void write(const cv::Mat& bgr) = 0;
  virtual void release() = 0;  // finishes the file
};

struct VideoPlugin {
  static constexpr int kVersion = 1;
  int version = kVersion;
  // cv::VideoWriter(file, fourcc, fps, size): nullptr when it cannot be opened.
  std::unique_ptr<VideoOut> (*open)(const std::string& file, const std::string& fourcc, double fps, cv::Size size) =
      nullptr;
};

}  // namespace previz::composite::detail
