#pragma once
// The previz_video plugin (take/plugin/video.cpp): every call into FFmpeg's libav* and OpenCV's
// videoio behind take/video.h and take/live.h. Loaded the first time a video is written, probed
// or read, or a live camera is opened (core/plugin.h): videoio and libavformat bring 244 and
// 134 shared libraries, which a command that reads image sequences need not load.
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "take/video.h"

namespace previz::take::detail {

// VideoWriter's work (video.h).
class VideoFileWriter {
 public:
  virtual ~VideoFileWriter() = default;
  virtual void write(const cv::Mat& bgr) = 0;
  virtual void close() = 0;
  virtual long long framesWritten() const = 0;
};

// VideoReader's work (video.h).
class VideoFileReader {
 public:
  virtual ~VideoFileReader() = default;
  virtual VideoReader::Frame read(long long index) = 0;
  virtual long long decodableFrames() = 0;
};

// A live source through cv::VideoCapture (live.h).
class LiveCapture {
 public:
  virtual ~LiveCapture() = default;
  virtual double fps() const = 0;  // CAP_PROP_FPS as the source says it
  virtual bool grab() = 0;
  virtual bool read(cv::Mat& frame) = 0;  // the frame as captured
};

struct VideoPlugin {
  static constexpr int kVersion = 1;
  int version = kVersion;
  // The options are validated by the caller. Errors: previz::Error naming the file.
  std::unique_ptr<VideoFileWriter> (*open_writer)(const std::filesystem::path& path, cv::Size size,
                                                  const VideoWriterOptions& options) = nullptr;
  VideoProbe (*probe)(const std::filesystem::path& path) = nullptr;
  std::unique_ptr<VideoFileReader> (*open_reader)(const std::filesystem::path& path, int prefetch) = nullptr;
  // nullptr when OpenCV cannot open the source (a device index, a GStreamer pipeline with '!',
  // or anything FFmpeg opens).
  std::unique_ptr<LiveCapture> (*open_live)(const std::string& source) = nullptr;
};

// The plugin, loaded on the first call (take/video.cpp). Throws Error naming its path when it
// is missing or cannot be loaded.
const VideoPlugin& videoPlugin();

// 23.976, 29.97, 59.94 (and 23.98, as people write it) are n*1000/1001 frames a second: the
// numerator n*1000 'fps' stands for, or 0 when it is not such a rate. av_d2q alone would give
// 2997/125 for 23.976, a rate no camera runs at and no timecode muxer accepts.
inline int ntscRateNumerator(double fps) {
  const double nominal = std::round(fps * 1.001);
  const bool integral = std::abs(fps - std::round(fps)) < 0.005;
  if (!integral && std::abs(fps - nominal * 1000.0 / 1001.0) < 0.005) return static_cast<int>(nominal) * 1000;
  return 0;
}

}  // namespace previz::take::detail
